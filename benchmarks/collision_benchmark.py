"""Collision-detection throughput: contacts per second on three scenes (not a test).

    python benchmarks/collision_benchmark.py [--repeat N]

Scenes: 1 000 and 10 000 spheres (r = 5 cm) settled in a 1 m-wide box of five planes, packed
as they rest (every sphere touching its neighbours and the floor), and a 100-level pyramid
of 0.1 m cubes (5 050 boxes, 5 mm gaps). Each is timed over several calls of
``collide(model, state)`` after a first call that compiles the kernels; the table gives the
median time per call, contacts found, contacts per second, and the broad phase's share.

A second table times the manifolds kept across steps (``collide_keeping``, docs/collision.md)
on resting scenes: the pyramid, and 108 convex hulls of 40 points settled on the ground by the
``constraints`` method: a fresh ``collide`` against a call that reuses what the previous step
kept, after every body has moved 10 µm (within the 0.1 mm tolerance). For the hulls it also
gives ``constraints`` steps per second over 1 s from the settled state, with and without.
"""

import argparse
import time

import numpy as np

from contactlab import ModelBuilder, collide, simulate
from contactlab.collision import DetectionSettings, _bounds, collide_keeping, colliders, state_poses
from contactlab.collision.broad_phase import overlapping_pairs


def sphere_pile(count, radius=0.05):
    """Spheres on a square grid of layers, touching: a settled pile in a box of width ~ sqrt(count/layers)."""
    b = ModelBuilder()
    side = int(np.ceil(np.sqrt(count / 10)))  # 10 layers
    spacing = 2 * radius * 0.999  # 0.1 % overlap: every neighbour touches
    for k in range(count):
        layer, rest = divmod(k, side * side)
        i, j = divmod(rest, side)
        b.add_body("sphere", radius=radius, mass=1.0, position=(i * spacing, j * spacing, radius + layer * spacing))
    half = side * spacing / 2
    b.add_obstacle("plane", normal=(0, 0, 1))
    for n, offset in (((1, 0, 0), -0.06), ((-1, 0, 0), -(2 * half)), ((0, 1, 0), -0.06), ((0, -1, 0), -(2 * half))):
        b.add_obstacle("plane", normal=n, offset=offset)
    return b.finalize()


def box_pyramid(levels, half=0.05, gap=0.005):
    b = ModelBuilder()
    for level in range(levels):
        n = levels - level
        for i in range(n):
            b.add_body(
                "box",
                half_extents=(half, half, half),
                mass=1.0,
                position=((i - (n - 1) / 2) * (2 * half + gap), 0, half * 0.999 + 2 * half * 0.999 * level),
            )
    b.add_obstacle("plane", normal=(0, 0, 1))
    return b.finalize()


def measure(name, model, repeat):
    state = model.state()
    contacts = collide(model, state)  # compiles on first use
    times, broad = [], []
    for _ in range(repeat):
        t0 = time.perf_counter()
        table = colliders(model)
        centers, rots = state_poses(model, state)
        lower, upper = _bounds(table.kinds, table.params, centers, rots, np.zeros(len(table.kinds)))
        overlapping_pairs(lower[: model.body_count], upper[: model.body_count])
        t1 = time.perf_counter()
        contacts = collide(model, state)
        t2 = time.perf_counter()
        broad.append(t1 - t0)
        times.append(t2 - t1)
    seconds = float(np.median(times))
    print(
        f"| {name} | {model.body_count} | {contacts.count} | {seconds * 1e3:.2f} | "
        f"{contacts.count / seconds:,.0f} | {np.median(broad) / seconds:.0%} |"
    )


def hull_stack(seed=0):
    """108 hulls of 40 random points on a 5 cm sphere, three layers on a 6 × 6 grid, settled
    for 1.5 s by ``constraints`` (dt 1/240, 50 sweeps): (model, settled state)."""
    rng = np.random.default_rng(seed)
    points = rng.normal(size=(40, 3))
    points = 0.05 * points / np.linalg.norm(points, axis=1)[:, None]
    b = ModelBuilder()
    b.add_material("m", friction=0.6, restitution=0.0)
    for i in range(6):
        for j in range(6):
            for level in range(3):
                b.add_body(
                    "convex",
                    points=points.tolist(),
                    mass=1.0,
                    position=(0.11 * i, 0.11 * j, 0.06 + 0.1 * level),
                    material="m",
                )
    b.add_obstacle("plane", normal=(0, 0, 1), material="m")
    model = b.finalize()
    return model, simulate(model, "constraints", 1 / 240, 1.5, {"iterations": 50}).state


def measure_kept(name, model, state, repeat, tolerance=1e-4, margin=0.002):
    """Fresh ``collide`` against ``collide_keeping`` reusing the manifolds of a call 10 µm back."""
    _, kept = collide_keeping(model, state, None, tolerance, DetectionSettings(margin))
    moved = state.copy()
    moved.body_position += 1e-5
    collide(model, moved, margin)
    fresh, reused = [], []
    for _ in range(repeat):
        t0 = time.perf_counter()
        collide(model, moved, margin)
        t1 = time.perf_counter()
        contacts, _ = collide_keeping(model, moved, kept, tolerance, DetectionSettings(margin))
        t2 = time.perf_counter()
        fresh.append(t1 - t0)
        reused.append(t2 - t1)
    print(
        f"| {name} | {model.body_count} | {contacts.count} | {len(kept)} | {np.median(fresh) * 1e3:.2f} | "
        f"{np.median(reused) * 1e3:.2f} |"
    )


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=10)
    args = parser.parse_args()
    print("| scene | bodies | contacts | ms per collide | contacts/s | broad phase share |")
    print("|---|---|---|---|---|---|")
    measure("sphere pile 1k", sphere_pile(1000), args.repeat)
    measure("sphere pile 10k", sphere_pile(10000), args.repeat)
    measure("box pyramid 100 levels", box_pyramid(100), args.repeat)
    print()
    print("| resting scene | bodies | contacts | kept pairs | ms per collide | ms reusing kept manifolds |")
    print("|---|---|---|---|---|---|")
    pyramid = box_pyramid(100)
    measure_kept("box pyramid 100 levels", pyramid, pyramid.state(), args.repeat)
    model, settled = hull_stack()
    measure_kept("hull stack", model, settled, args.repeat)
    print()
    for tolerance in (0.0, 1e-4):
        run = simulate(
            model, "constraints", 1 / 240, 1.0, {"iterations": 50, "manifold_tolerance": tolerance}, state=settled
        )
        print(
            f"hull stack, constraints, manifold_tolerance {tolerance:g}: {run.summary['steps_per_second']:.1f} steps/s"
        )


if __name__ == "__main__":
    main()
