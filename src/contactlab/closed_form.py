"""Closed-form answers of the built-in scenes, and what a run measured of them.

    for check in checks("sliding_block", scene.model, run.arrays):
        print(check.quantity, check.expected, check.measured, check.error)

Every expected value is computed from the model itself (masses, radii, μ, ε, gravity, the
initial state), so a scene changed with ``--set`` is still checked against its own answer; a
scene changed so far that the formula no longer applies (another shape, a second body) gets no
check rather than a wrong one. Measurements read the recorded trajectory (docs/trajectory.md).
Friction and restitution combine as in contact generation: μ = √(μ_a μ_b), ε = max(ε_a, ε_b).

Each check also carries the scene's verdict: ``tolerance``, the largest |measured − expected|
its stated expectation allows, and ``passed``. How the tolerances are set, once for all scenes:

* a closed-form value must be met to ``RELATIVE`` (2 %) of itself — close enough that the
  physics is unmistakably the lecture's (a bounce that loses 4 % too little energy, a block
  that stops 2 % early, fail) and loose enough for a first-order step of the scene's own size;
* plus a floor in the quantity's kind, for values that are 0 or read at sample times: one
  sample interval for a time, ``LENGTH_FLOOR`` for a length, ``SPEED_FLOOR`` of the scene's
  own speed for a velocity;
* a structure that must stand: every body within ``STANDING`` (1 cm) of its start at every
  sample, the bound the scenes' descriptions state (and ``SINKING``, 5 mm of overlap, where
  they say nothing may sink);
* G1 for piles, particles and cloth: no centre of a body or particle ever inside a static
  obstacle (tolerance 0), and no overlap deeper than ``OVERLAP_SHARE`` of the smallest radius;
* a cloth that folds onto itself: no edge through the cloth (tolerance 0), and a heap whose
  height lies between the bounds its contact distances set (:func:`_cloth_fold`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from . import rotations, shapes

if TYPE_CHECKING:
    from .model import Model

RELATIVE = 0.02  # share of a closed-form value its measurement may miss it by
LENGTH_FLOOR = 1e-3  # m: a length's tolerance besides RELATIVE (expected values of 0)
SPEED_FLOOR = 0.01  # share of the scene's initial speed a velocity's tolerance has besides RELATIVE
STANDING = 0.01  # m: how far a body of a structure that must stand may move (the scenes say < 1 cm)
SINKING = 0.005  # m: the deepest overlap of a stack that must not sink (box_stack says 5 mm)
OVERLAP_SHARE = 0.1  # of the smallest radius: the deepest overlap of a pile that must not sink into itself


@dataclass(frozen=True)
class Check:
    quantity: str
    """what is compared, e.g. "first rebound apex" """
    unit: str
    """of expected and measured, e.g. "m" """
    expected: float
    """the closed-form value"""
    measured: float
    """what the run gave (nan when the run never reached it)"""
    tolerance: float | None = None
    """the largest |measured − expected| the scene's expectation allows, in ``unit``"""

    @property
    def passed(self) -> bool | None:
        """The verdict: True when the measurement is within ``tolerance`` of the expected value,
        False when it is not (or was never reached), None for a check without a tolerance."""
        if self.tolerance is None:
            return None
        return bool(np.isfinite(self.measured) and abs(self.error) <= self.tolerance)

    def as_record(self) -> dict:
        """The check as plain data (summary.json's ``checks``, a sweep's ``closed_form_checks``):
        quantity, unit, expected, measured (None: not reached), tolerance, passed."""
        return {
            "quantity": self.quantity,
            "unit": self.unit,
            "expected": float(self.expected),
            "measured": float(self.measured) if np.isfinite(self.measured) else None,
            "tolerance": self.tolerance,
            "passed": self.passed,
        }

    def verdict(self) -> str:
        """One line: "<quantity>: <measured> <unit> (expected <e> ± <tolerance>): pass|FAIL"."""
        measured = f"{self.measured:.4g} {self.unit}" if np.isfinite(self.measured) else "not reached"
        allowed = f" ± {self.tolerance:.2g}" if self.tolerance is not None else ""
        word = {True: "pass", False: "FAIL", None: "no verdict"}[self.passed]
        return f"{self.quantity}: {measured} (expected {self.expected:.4g}{allowed}): {word}"

    @property
    def error(self) -> float:
        """measured − expected, in ``unit``."""
        return self.measured - self.expected

    @property
    def relative_error(self) -> float | None:
        """|error| / |expected|; None when the expected value is 0 (compare ``error`` instead)."""
        return abs(self.error) / abs(self.expected) if self.expected != 0 else None


def checks(scene_name: str, model: Model | None, arrays: Mapping[str, Any]) -> list[Check]:
    """The closed-form checks of built-in scene ``scene_name`` on a run's ``arrays``; [] when the
    scene has none or no longer has the layout its formula needs."""
    check = _CHECKS.get(scene_name)
    return check(model, arrays) if check and model is not None else []


def _relative(expected, floor):
    """The tolerance of a closed-form value: RELATIVE of it, plus ``floor`` (its kind's)."""
    return RELATIVE * abs(float(expected)) + floor


def _sample_interval(arrays):
    """The largest time between two samples [s] (0 with one sample)."""
    time = np.asarray(arrays["time"])
    return float(np.diff(time).max()) if len(time) > 1 else 0.0


# ---- what the formulas need of a scene ---------------------------------------------------------


def _gravity(model):
    """(|g| [m/s²], unit vector 'up' (3,)); up is None without gravity."""
    g = float(np.linalg.norm(model.gravity))
    return g, (-np.asarray(model.gravity) / g if g > 0 else None)


def _one_body_on_plane(model, kind):
    """(body shape params, plane params) when the scene is one body of ``kind`` and one plane."""
    if (
        model.body_count != 1
        or model.particle_count
        or model.obstacle_count != 1
        or model.body_shape[0] != kind
        or model.obstacle_shape[0] != shapes.PLANE
    ):
        return None
    return model.body_params[0], model.obstacle_params[0]


def _body_on_floor(model, kind):
    """(shape params (4,), |g|, up (3,), floor offset along up, and the contact's μ and ε) when
    the scene is one body of ``kind`` on one horizontal plane under gravity; else None."""
    layout = _one_body_on_plane(model, kind)
    g, up = _gravity(model)
    floor = _horizontal_floor(model, up) if layout is not None else None
    return None if floor is None else (layout[0], g, up, floor, *_materials(model))


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
    params, g, up, floor, _, restitution = layout
    height = arrays["body_position"][:, 0] @ up - floor - params[0]
    rise = arrays["body_velocity"][:, 0] @ up
    h0 = float(height[0])
    if np.linalg.norm(arrays["body_velocity"][0, 0]) > 0:
        return []
    # apexes: where the upward speed turns from positive to non-positive
    turning = np.flatnonzero((rise[:-1] > 0) & (rise[1:] <= 0))
    apexes = [float(height[i : i + 2].max()) for i in turning]
    return [
        Check(
            f"rebound {n} apex",
            "m",
            restitution ** (2 * n) * h0,
            apexes[n - 1] if len(apexes) >= n else float("nan"),
            _relative(restitution ** (2 * n) * h0, LENGTH_FLOOR),
        )
        for n in (1, 2)
    ]


def _sliding_block(model, arrays):
    """A block launched at v0 on a floor stops after v0²/(2 μ g), at t = v0/(μ g)."""
    layout = _body_on_floor(model, shapes.BOX)
    if layout is None:
        return []
    _, g, up, _, friction, _ = layout
    v0 = np.linalg.norm(arrays["body_velocity"][0, 0] - (arrays["body_velocity"][0, 0] @ up) * up)
    if friction == 0 or v0 == 0:
        return []
    moved = arrays["body_position"][:, 0] - arrays["body_position"][0, 0]
    moved -= np.outer(moved @ up, up)
    speed = np.linalg.norm(arrays["body_velocity"][:, 0], axis=1)
    distance, stop = v0**2 / (2 * friction * g), v0 / (friction * g)
    return [
        Check("stopping distance", "m", distance, float(np.linalg.norm(moved[-1])), _relative(distance, LENGTH_FLOOR)),
        Check(
            "stopping time",
            "s",
            stop,
            _first_time(arrays["time"], speed < 1e-3 * v0),
            _relative(stop, _sample_interval(arrays)),
        ),
    ]


def _rolling_sphere(model, arrays):
    """A ball launched at v0 without spin slides until t = 2 v0/(7 μ g), then rolls at 5/7 v0."""
    layout = _body_on_floor(model, shapes.SPHERE)
    if layout is None:
        return []
    params, g, up, _, friction, _ = layout
    radius = params[0]
    v = arrays["body_velocity"][:, 0]
    w = arrays["body_angular_velocity"][:, 0]
    v0 = float(np.linalg.norm(v[0]))
    if friction == 0 or v0 == 0 or np.linalg.norm(w[0]) > 0:
        return []
    slip = np.linalg.norm(v + np.cross(w, -radius * up), axis=1)  # velocity of the touching point
    sliding = 2.0 * v0 / (7.0 * friction * g)
    # the slip falls linearly to 0, so it crosses the 1 % read here 1 % of the time early
    return [
        Check(
            "rolling speed",
            "m/s",
            5.0 / 7.0 * v0,
            float(np.linalg.norm(v[-1])),
            _relative(5.0 / 7.0 * v0, SPEED_FLOOR * v0),
        ),
        Check(
            "end of sliding",
            "s",
            sliding,
            _first_time(arrays["time"], slip < 0.01 * v0),
            _relative(sliding, 0.01 * sliding + _sample_interval(arrays)),
        ),
    ]


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
    sin_theta = float(np.sqrt(max(0.0, 1.0 - cos_theta**2)))
    friction, _ = _materials(model)
    acceleration = max(0.0, g * (sin_theta - friction * cos_theta))
    elapsed = float(arrays["time"][-1] - arrays["time"][0])
    moved = float((arrays["body_position"][-1, 0] - arrays["body_position"][0, 0]) @ downhill)
    expected = 0.5 * acceleration * elapsed**2
    return [Check("distance down the slope", "m", expected, moved, _relative(expected, LENGTH_FLOOR))]


def _newtons_cradle(model, arrays):
    """Equal balls, ε = 1, no gravity: the striker's velocity ends in the last ball, the others stop."""
    if (
        model.body_count < 2
        or model.obstacle_count
        or model.particle_count
        or np.any(model.gravity != 0)
        or np.any(model.body_shape != shapes.SPHERE)
        or np.ptp(model.body_mass) > 0
        or np.any(model.material_restitution[model.body_material] != 1.0)
    ):
        return []
    v = arrays["body_velocity"]
    v0 = v[0, 0]
    if np.linalg.norm(v0) == 0 or np.any(np.linalg.norm(v[0, 1:], axis=1) > 0):
        return []
    speed = float(np.linalg.norm(v0))
    direction = v0 / speed
    return [
        Check("last ball velocity", "m/s", speed, float(v[-1, -1] @ direction), _relative(speed, SPEED_FLOOR * speed)),
        Check(
            "largest speed of the other balls",
            "m/s",
            0.0,
            float(np.linalg.norm(v[-1, :-1], axis=1).max()),
            SPEED_FLOOR * speed,
        ),
    ]


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
    params, g, up, floor, friction, restitution = layout
    if (
        friction != 0
        or np.linalg.norm(arrays["body_velocity"][0, 0]) > 0
        or np.linalg.norm(arrays["body_angular_velocity"][0, 0]) > 0
    ):
        return []
    R = rotations.to_matrix(arrays["body_orientation"][0, :1])[0]  # unchanged while falling
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * params[:3]
    r = min(corners @ R.T, key=lambda c: c @ up)  # the lowest corner, from the centre, world
    drop = float((arrays["body_position"][0, 0] + r) @ up - floor)
    impact_time = arrays["time"][0] + np.sqrt(2.0 * drop / g)
    v_normal = -np.sqrt(2.0 * g * drop)
    inverse_inertia = R @ np.diag(1.0 / model.body_inertia[0]) @ R.T
    effective = 1.0 / model.body_mass[0] + up @ np.cross(inverse_inertia @ np.cross(r, up), r)
    j = -(1.0 + restitution) * v_normal / effective
    v_after = v_normal + j / model.body_mass[0]
    w_after = inverse_inertia @ np.cross(r, j * up)
    axis = int(np.argmax(np.abs(w_after)))  # the impact is planar: one axis spins
    touching = arrays["contact_count"] > 0
    first = np.argmax(touching) if touching.any() else len(touching)
    after = np.flatnonzero(~touching & (np.arange(len(touching)) > first))
    if len(after):
        k = after[0]
        measured_v = float(arrays["body_velocity"][k, 0] @ up + g * (arrays["time"][k] - impact_time))
        measured_w = float(arrays["body_angular_velocity"][k, 0, axis])
    else:
        measured_v = measured_w = float("nan")
    return [
        Check(
            "vertical velocity after the impact",
            "m/s",
            float(v_after),
            measured_v,
            _relative(v_after, SPEED_FLOOR * abs(v_normal)),
        ),
        Check(
            f"angular velocity about {'xyz'[axis]} after the impact",
            "rad/s",
            float(w_after[axis]),
            measured_w,
            _relative(w_after[axis], 0.0),
        ),
    ]


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
    if (
        drive is None
        or model.body_count != 2
        or model.particle_count
        or model.obstacle_count != 1
        or up is None
        or _horizontal_floor(model, up) is None
        or model.body_shape[0] != shapes.BOX
        or list(np.flatnonzero(drive.kinematic)) != [1]
        or list(drive.path_body) != [1]
        or drive.has_loads
        or len(drive.path_times[0]) != 2
    ):
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
    first = _first_time(time, along > 0.5 * speed)  # the first contact
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
    return [
        Check("box speed while pushed", "m/s", speed, mean_speed, _relative(speed, SPEED_FLOOR * speed)),
        Check(
            "push force: the sliding friction it balances",
            "N",
            friction * mass * g,
            force,
            _relative(friction * mass * g, 0.0),
        ),
    ]


def _standing(model, arrays):
    """A structure in static equilibrium must not move: every body within STANDING of its start
    at every sample (the largest displacement of any body over the run)."""
    if model.body_count == 0:
        return []
    positions = np.asarray(arrays["body_position"])
    moved = np.linalg.norm(positions - positions[:1], axis=2)
    return [Check("largest body displacement", "m", 0.0, float(moved.max()), STANDING)]


def _standing_unsunk(model, arrays):
    """A stack must stand and nothing may sink: :func:`_standing`, and no overlap deeper than SINKING."""
    found = _standing(model, arrays)
    return (
        found + [Check("deepest overlap", "m", 0.0, float(np.max(arrays["max_penetration"])), SINKING)] if found else []
    )


def _centres_inside_obstacles(model, positions):
    """The deepest any centre (positions (T, K, 3)) gets inside a static plane, sphere or box
    obstacle [m], 0 when none ever does (meshes are two-sided: they have no inside)."""
    from .collision.signed_distance import points_against_shape

    points = np.ascontiguousarray(positions.reshape(-1, 3), dtype=float)
    deepest = 0.0
    for index in range(model.obstacle_count):
        kind = int(model.obstacle_shape[index])
        if kind not in (shapes.PLANE, shapes.SPHERE, shapes.BOX) or not len(points):
            continue
        rotation = rotations.to_matrix(np.asarray(model.obstacle_orientation[index], dtype=float)[None])[0]
        signed = points_against_shape(
            points,
            kind,
            np.asarray(model.obstacle_params[index], dtype=float),
            np.asarray(model.obstacle_position[index], dtype=float),
            rotation,
        )[0]
        deepest = max(deepest, float(-signed.min()))
    return deepest


def _kept_out(model, arrays):
    """G1 for a pile, particles or cloth: no centre of a body or particle (cloth vertex) ever
    inside a static obstacle, and no overlap deeper than OVERLAP_SHARE of the smallest radius."""
    if model.body_count + model.particle_count == 0 or model.obstacle_count == 0:
        return []
    positions = np.concatenate([np.asarray(arrays["body_position"]), np.asarray(arrays["particle_position"])], axis=1)
    radius = _smallest_radius(model)
    found = [Check("deepest centre inside an obstacle", "m", 0.0, _centres_inside_obstacles(model, positions), 0.0)]
    if np.isfinite(radius):
        found.append(
            Check("deepest overlap", "m", 0.0, float(np.max(arrays["max_penetration"])), OVERLAP_SHARE * radius)
        )
    return found


def _smallest_radius(model):
    """The smallest radius [m] of a sphere, capsule or particle of the scene (inf with none)."""
    radii = [np.asarray(model.particle_radius, dtype=float)]
    for kind in (shapes.SPHERE, shapes.CAPSULE):
        radii.append(np.asarray(model.body_params, dtype=float)[np.asarray(model.body_shape) == kind, 0])
    every = np.concatenate(radii)
    return float(every.min()) if every.size else float("inf")


def _in_the_bowl(model, arrays):
    """Everything dropped into a mesh bowl ends inside it: the largest distance of an end
    position outside the bowl's bounds [m] (its vertices' box), 0 when all are in."""
    meshes = [
        int(model.obstacle_params[i, 0]) for i in range(model.obstacle_count) if model.obstacle_shape[i] == shapes.MESH
    ]
    if len(meshes) != 1 or model.body_count + model.particle_count == 0:
        return []
    vertices = np.asarray(model.meshes[meshes[0]].vertices, dtype=float)
    low, high = vertices.min(axis=0), vertices.max(axis=0)
    ends = np.concatenate([np.asarray(arrays["body_position"][-1]), np.asarray(arrays["particle_position"][-1])])
    outside = np.maximum(np.maximum(low - ends, ends - high), 0.0)
    outside[:, 2] = np.maximum(low[2] - ends[:, 2], 0.0)  # open at the top: only below counts
    return [
        Check(
            "largest distance of an end position outside the bowl",
            "m",
            0.0,
            float(np.linalg.norm(outside, axis=1).max()),
            0.0,
        )
    ]


def _domino_chain(model, arrays):
    """The fall runs down the whole chain: the last domino ends tipped over, its long axis
    turned 90° from upright (within 45°: past its tipping angle, lying or leaning)."""
    if model.body_count < 2 or np.any(model.body_shape != shapes.BOX):
        return []
    g, up = _gravity(model)
    if up is None:
        return []
    long_axis = int(np.argmax(model.body_params[-1, :3]))
    start = rotations.to_matrix(np.asarray(arrays["body_orientation"][0, -1:], dtype=float))[0][:, long_axis]
    end = rotations.to_matrix(np.asarray(arrays["body_orientation"][-1, -1:], dtype=float))[0][:, long_axis]
    if abs(start @ up) < 0.99:  # the last domino does not start upright
        return []
    tilt = float(np.degrees(np.arccos(np.clip(abs(end @ up), 0.0, 1.0))))
    return [Check("tilt of the last domino", "deg", 90.0, tilt, 45.0)]


def _cloth_fold(model, arrays):
    """A strip stood on its foot piles up on the floor in folds, layer on layer, and never passes
    through itself. Two checks:

    * no crossing: the most edges through a triangle of the cloth (its own or another cloth's,
      ``collision.cloth_self.crossings`` over every cloth, self-contact on or off) in any sample,
      beyond those of the first sample; expected 0, tolerance 0;
    * the heap's height, its highest vertex above the floor at the last sample [m], between two
      bounds that follow from the contact distances (a vertex is a particle of radius
      ``thickness`` t: the floor holds it t above, self-contact holds two layers 2t apart):
      at least two layers, 3t (a strip that toppled flat, or never folded onto itself, lies at t),
      and at most every row of vertices along the strip a layer of its own resting on the one
      below, t + (rows − 1)·2t (anything higher still stands or leans: not yet piled). A Check
      is symmetric: expected is the middle of the two bounds, tolerance half their distance.
    """
    _, up = _gravity(model)
    floor = _horizontal_floor(model, up) if model.obstacle_count else None
    cloth = np.flatnonzero(np.asarray(model.particle_cloth) >= 0)
    if floor is None or model.cloth_count != 1 or model.body_count or len(cloth) != model.particle_count:
        return []
    from .collision.cloth_self import crossings

    positions = np.asarray(arrays["particle_position"], dtype=float)
    counts = [len(crossings(model, sample, every_cloth=True)) for sample in positions]
    thickness = float(np.min(model.particle_radius))
    start = np.asarray(model.initial.particle_position, dtype=float)
    along = int(np.argmax(np.ptp(start, axis=0)))  # the strip's length
    rows = len(np.unique(np.round(start[:, along], 9)))
    low, high = 3.0 * thickness, thickness + (rows - 1) * 2.0 * thickness
    height = float(np.max(positions[-1] @ up) - floor)
    return [
        Check("edges through the cloth", "edges", 0.0, float(max(counts) - counts[0]), 0.0),
        Check("heap height", "m", (low + high) / 2, height, (high - low) / 2),
    ]


_CHECKS = {
    "bouncing_ball": _bouncing_ball,
    "sliding_block": _sliding_block,
    "rolling_sphere": _rolling_sphere,
    "incline": _incline,
    "newtons_cradle": _newtons_cradle,
    "rod_impact": _rod_impact,
    "box_stack": _standing_unsunk,
    "box_pyramid": _standing,
    "mass_ratio_stack": _standing_unsunk,
    "card_house": _standing,
    "box_pushed": _box_pushed,
    "sphere_pile": _kept_out,
    "capsule_pile": _kept_out,
    "particles_box": _kept_out,
    "cloth_drape": _kept_out,
    "cloth_fold": _cloth_fold,
    "mesh_bowl": _in_the_bowl,
    "particles_bowl": _in_the_bowl,
    "domino_chain": _domino_chain,
}
