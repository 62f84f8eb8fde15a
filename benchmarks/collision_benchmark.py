"""Collision-detection throughput: contacts per second on three scenes (not a test).

    python benchmarks/collision_benchmark.py [--repeat N]

Scenes: 1 000 and 10 000 spheres (r = 5 cm) settled in a 1 m-wide box of five planes, packed
as they rest (every sphere touching its neighbours and the floor), and a 100-level pyramid
of 0.1 m cubes (5 050 boxes, 5 mm gaps). Each is timed over several calls of
``collide(model, state)`` after a first call that compiles the kernels; the table gives the
median time per call, contacts found, contacts per second, and the broad phase's share.
"""

import argparse
import time

import numpy as np

from contactlab import ModelBuilder, collide
from contactlab.collision import _bounds, _colliders
from contactlab.collision.broad_phase import overlapping_pairs


def sphere_pile(count, radius=0.05):
    """Spheres on a square grid of layers, touching: a settled pile in a box of width ~ sqrt(count/layers)."""
    b = ModelBuilder()
    side = int(np.ceil(np.sqrt(count / 10)))          # 10 layers
    spacing = 2 * radius * 0.999                        # 0.1 % overlap: every neighbour touches
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
            b.add_body("box", half_extents=(half, half, half), mass=1.0,
                       position=((i - (n - 1) / 2) * (2 * half + gap), 0, half * 0.999 + 2 * half * 0.999 * level))
    b.add_obstacle("plane", normal=(0, 0, 1))
    return b.finalize()


def measure(name, model, repeat):
    state = model.state()
    contacts = collide(model, state)                    # compiles on first use
    times, broad = [], []
    for _ in range(repeat):
        t0 = time.perf_counter()
        kinds, params, centers, rots = _colliders(model, state)
        lower, upper = _bounds(kinds, params, centers, rots, np.zeros(len(kinds)))
        overlapping_pairs(lower[:model.body_count], upper[:model.body_count])
        t1 = time.perf_counter()
        contacts = collide(model, state)
        t2 = time.perf_counter()
        broad.append(t1 - t0)
        times.append(t2 - t1)
    seconds = float(np.median(times))
    print(f"| {name} | {model.body_count} | {contacts.count} | {seconds * 1e3:.2f} | "
          f"{contacts.count / seconds:,.0f} | {np.median(broad) / seconds:.0%} |")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=10)
    args = parser.parse_args()
    print("| scene | bodies | contacts | ms per collide | contacts/s | broad phase share |")
    print("|---|---|---|---|---|---|")
    measure("sphere pile 1k", sphere_pile(1000), args.repeat)
    measure("sphere pile 10k", sphere_pile(10000), args.repeat)
    measure("box pyramid 100 levels", box_pyramid(100), args.repeat)


if __name__ == "__main__":
    main()
