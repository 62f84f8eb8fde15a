"""What is measured of each method's run: the numbers of its row in comparison.csv, the
verdict on the scene's stated expectations, and which runs computed the same trajectory.

The columns and their units are defined in docs/compare.md; contactlab.sweep measures its
cells with :func:`metrics` too.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from .. import closed_form
from ..plots import total_energy

if TYPE_CHECKING:
    from ..closed_form import Check
    from ..model import Model
    from .run import Outcome

TIMINGS = (
    "steps_per_second",
    "steps_per_second_median",
    "steps_per_second_low",
    "steps_per_second_high",
    "wall_seconds",
)  # the row's keys that differ from one run of the same computation to the next
TINY_ENERGY = 1e-9  # J: an energy scale below this (times max(1, |E(0)|)) gives no relative drift
SAME_WITHIN = 1e-9  # m (and unit quaternion components): trajectories this close are one computation
# the keys of a row, in the order of comparison.csv's header; the checks' error columns follow them
ROW_KEYS = (
    "method",
    "status",
    "expectations",
    "integrator",
    "dt_s",
    "steps",
    *TIMINGS,
    "max_contacts",
    "max_penetration_mm",
    "mean_penetration_mm",
    "energy_drift_J",
    "energy_drift_relative",
    "momentum_drift_Ns",
    "max_solver_iterations",
    "mean_solver_iterations",
    "max_solver_residual",
)


def energy_scale(model: Model, arrays: Mapping[str, Any]) -> float:
    """The energy [J] a drift is measured against: the larger of (a) the most mechanical energy
    the run ever held above the lowest potential energy it reached, max (K + V) − min V, and
    (b) the potential energy of the initial configuration above its own lowest mass,
    Σ m_i |g| (h_i − min h), h the height against gravity (bodies' centres and particles).

    The contact springs' elastic energy (penalty's alone) is left out: its peak depends on
    the method's stiffness, not on the scene, so with it each method's drift would be divided
    by a different number, and a method whose springs stored much would look better for it."""
    mechanical = np.asarray(arrays["energy_kinetic"]) + np.asarray(arrays["energy_potential"])
    held = float(mechanical.max() - np.min(arrays["energy_potential"]))
    g = np.asarray(model.gravity, dtype=float)
    masses = np.concatenate([model.body_mass, model.particle_mass])
    if not masses.size or not np.any(g):
        return held
    positions = np.concatenate([arrays["body_position"][0], arrays["particle_position"][0]])
    heights = -(positions @ g) / np.linalg.norm(g)
    stored = float(np.linalg.norm(g) * masses @ (heights - heights.min()))
    return max(held, stored)


def momentum_drift(model: Model, arrays: Mapping[str, Any]) -> float | None:
    """‖P(T) − P(0) − M g T‖ [N·s], P = Σ m v over bodies and particles, M g T the impulse of
    gravity over the run. None when the scene has static obstacles or pinned particles: their
    forces are external, so momentum is not conserved and the number means nothing."""
    if model.obstacle_count or (model.particle_pinned is not None and np.any(model.particle_pinned)):
        return None
    momentum = model.body_mass @ arrays["body_velocity"] + model.particle_mass @ arrays["particle_velocity"]
    elapsed = float(arrays["time"][-1] - arrays["time"][0])
    mass = float(np.sum(model.body_mass) + np.sum(model.particle_mass))
    return float(np.linalg.norm(momentum[-1] - momentum[0] - mass * np.asarray(model.gravity) * elapsed))


def _rates(summary):
    """steps/s: the whole run's, and as repeated measurements the median over its ~0.1 s
    windows of stepping and their quartiles (summary.json's ``steps_per_second_spread``; None
    for a run too short to time)."""
    spread = summary.get("steps_per_second_spread")
    if not spread:
        return {
            "steps_per_second": summary["steps_per_second"],
            "steps_per_second_median": None,
            "steps_per_second_low": None,
            "steps_per_second_high": None,
        }
    return {
        "steps_per_second": summary["steps_per_second"],
        "steps_per_second_median": spread["median"],
        "steps_per_second_low": spread["low"],
        "steps_per_second_high": spread["high"],
    }


def metrics(model: Model, arrays: Mapping[str, Any], summary: Mapping[str, Any]) -> dict[str, Any]:
    """The numbers of one run (keys as in comparison.csv; units in docs/compare.md)."""
    energy = total_energy(arrays)
    drift = float(energy[-1] - energy[0])
    scale = energy_scale(model, arrays)
    momentum = momentum_drift(model, arrays)
    iterations = summary["solver"]["max_iterations"]
    return {
        "steps": summary["steps"],
        **_rates(summary),
        "wall_seconds": summary["wall_seconds"],
        "max_contacts": summary["max_contacts"],
        "max_penetration_mm": summary["max_penetration"] * 1000.0,
        "mean_penetration_mm": float(np.mean(arrays["max_penetration"])) * 1000.0,
        "energy_drift_J": drift,
        "energy_drift_relative": drift / scale if scale > TINY_ENERGY * max(1.0, abs(energy[0])) else None,
        "momentum_drift_Ns": "n/a" if momentum is None else momentum,
        "max_solver_iterations": iterations,
        "mean_solver_iterations": summary["solver"]["mean_iterations"],
        "max_solver_residual": summary["solver"]["max_residual"] if iterations else None,
    }


def expectation_verdict(checks: Sequence[Check]) -> str:
    """The scene's stated expectations on one run, in a word and a count: "pass (2 of 2)",
    "FAIL (1 of 2)" — met of those with a verdict —, or "n/a" when the scene states none."""
    judged = [check.passed for check in checks if check.passed is not None]
    if not judged:
        return "n/a"
    return f"{'pass' if all(judged) else 'FAIL'} ({sum(judged)} of {len(judged)})"


def _check_column(check) -> str:
    """The row key of a closed-form check's error (measured − expected), its unit in it."""
    return f"{check.quantity} error ({check.unit})"


def fill_rows(outcomes: Sequence[Outcome]) -> None:
    """Give each outcome (contactlab.compare.run) its ``row``: identity, status, metrics, and one
    error column per check quantity any of them has (None where a run has no such check), and
    its ``checks`` (contactlab.closed_form.Check)."""
    for outcome in outcomes:
        scene = outcome.scene
        row = {
            "method": outcome.method,
            "status": "ok" if outcome.run else f"not run: {outcome.gap}" if outcome.gap else blew_up(outcome),
            "integrator": outcome.integrator or scene.integrator,
            "dt_s": scene.dt,
        }
        if outcome.run:
            row.update(metrics(scene.model, outcome.run.arrays, outcome.run.summary))
            outcome.checks = closed_form.checks(scene.name, scene.model, outcome.run.arrays)
            row["expectations"] = expectation_verdict(outcome.checks)
        outcome.row = row
    check_columns = []
    for outcome in outcomes:
        for check in outcome.checks:
            if _check_column(check) not in check_columns:
                check_columns.append(_check_column(check))
    for outcome in outcomes:
        errors = {_check_column(check): check.error for check in outcome.checks}
        outcome.row = {key: outcome.row.get(key, errors.get(key)) for key in [*ROW_KEYS, *check_columns]}


def blew_up(outcome: Outcome) -> str:
    """The status of a run a health check stopped: "blew up at t = … s" (simulated time)."""
    return f"blew up at t = {outcome.failed_at:.4g} s" if outcome.failed_at is not None else "blew up"


def dissipative(model: Model) -> bool:
    """Whether the scene's contacts lose energy by design (restitution < 1 or friction > 0)."""
    used = np.concatenate([model.body_material, model.particle_material, model.obstacle_material]).astype(int)
    return bool(
        used.size and (np.any(model.material_restitution[used] < 1.0) or np.any(model.material_friction[used] > 0.0))
    )


def same_computation(outcomes: Sequence[Outcome]) -> list[tuple[list[str], float]]:
    """(method names, largest difference [m]) of each group of runs whose positions,
    orientations and particles agree within SAME_WITHIN at every sample: rounding, not physics."""
    ran = [outcome for outcome in outcomes if outcome.run is not None]
    series = {
        outcome.method: [
            np.asarray(outcome.run.arrays[name])  # type: ignore[union-attr]  # the runs that ran
            for name in ("body_position", "body_orientation", "particle_position")
        ]
        for outcome in ran
    }
    groups, placed = [], set()
    for index, outcome in enumerate(ran):
        if outcome.method in placed:
            continue
        group, largest = [outcome.method], 0.0
        for other in ran[index + 1 :]:
            if other.method in placed:
                continue
            mine, theirs = series[outcome.method], series[other.method]
            if all(a.shape == b.shape for a, b in zip(mine, theirs)):
                apart = [float(np.max(np.abs(a - b))) if a.size else 0.0 for a, b in zip(mine, theirs)]
                if max(apart) <= SAME_WITHIN:
                    group.append(other.method)
                    largest = max(largest, apart[0], apart[2])  # positions [m]
        if len(group) > 1:
            placed.update(group)
            groups.append((group, largest))
    return groups
