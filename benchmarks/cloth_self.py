"""What cloth self-contact costs: steps/s with and without it (not a test).

    python benchmarks/cloth_self.py [--duration S] [--quick]

Two scenes, each run with ``self_collision`` on (the default) and off, by the projection method
with the scene's backward Euler springs at 1/240 s (cloth_drape at its own 1/120 s):

* ``cloth_drape``, the built-in scene (25 × 25 vertices over a sphere), for ``--duration`` s;
* a folding 64 × 64 cloth: a 1 m square sheet (4 096 vertices, 0.3 kg, 4 mm thick) stood
  upright with its lower edge 1 mm above the floor and let go, so that it buckles and piles up
  in folds on itself; ``--quick``: 24 × 24.

For each run: the summary's steps/s (stepping only, compiling left out), the most contacts in a
step, the most self-contacts in a sample, whether an edge ever passed through a triangle
(``collision.cloth_self.crossings`` at every sample), and the ratio of the times per step. The
table is printed and written to ``benchmarks/results/cloth_self.md`` with the threads and the
machine's load average, which on a shared machine moves the numbers by ±20 %.
"""

import argparse
import os
import time

import numpy as np

from contactlab import ModelBuilder, simulate
from contactlab.collision.cloth_self import crossings
from contactlab.scene import load_scene
from contactlab.threads import set_threads

UPRIGHT = (np.cos(np.pi / 4), np.sin(np.pi / 4), 0.0, 0.0)  # 90° about x: the grid's y axis points up
RESULTS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results", "cloth_self.md")


def folding_cloth(n, self_collision):
    b = ModelBuilder()
    b.add_material("cotton", friction=0.4, restitution=0.0)
    b.add_cloth(
        size=(1.0, 1.0),
        resolution=(n, n),
        mass=0.3,
        position=(0.0, 0.0, 0.505),
        orientation=UPRIGHT,
        stretch_stiffness=1000.0,
        shear_stiffness=100.0,
        bend_stiffness=0.5,
        damping=0.01,
        thickness=0.004,
        material="cotton",
        self_collision=self_collision,
    )
    b.add_obstacle("plane", normal=(0, 0, 1), offset=0.0, material="cotton")
    return b.finalize()


def measure(label, model, twin, dt, duration, options, integrator):
    """One run; ``twin``: the same model with self-collision on, whose elements the crossings are counted over."""
    started = time.perf_counter()
    run = simulate(model, "projection", dt, duration, options, integrator, record_every=8, allow_divergence=True)
    wall = time.perf_counter() - started
    positions = run.arrays["particle_position"]
    crossed = sum(bool(len(crossings(twin, x))) for x in positions)
    return dict(
        label=label,
        vertices=model.particle_count,
        steps_per_second=run.summary["steps_per_second"],
        max_contacts=run.summary["max_contacts"],
        self_contacts=run.summary["self_contacts"],
        crossed=crossed,
        samples=len(positions),
        wall=wall,
        violations=[v["check"] for v in run.summary["health"]["violations"]],
    )


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=1.0, help="simulated seconds per run")
    parser.add_argument("--quick", action="store_true", help="a 24 × 24 folding cloth and 0.2 s runs")
    parser.add_argument("--threads", default="auto")
    args = parser.parse_args()
    duration = 0.2 if args.quick else args.duration
    n = 24 if args.quick else 64
    set_threads(args.threads)
    rows = []
    drape = load_scene("cloth_drape").model
    for on in (True, False):
        scene = load_scene("cloth_drape", [f"cloth[0].self_collision={'true' if on else 'false'}"])
        rows.append(
            measure(
                f"cloth_drape, self_collision = {str(on).lower()}",
                scene.model,
                drape,
                scene.dt,
                duration,
                scene.options.get("projection"),
                scene.integrator,
            )
        )
        print(rows[-1], flush=True)
    folding = folding_cloth(n, True)
    for on in (True, False):
        rows.append(
            measure(
                f"folding {n} × {n}, self_collision = {str(on).lower()}",
                folding_cloth(n, on),
                folding,
                1 / 240,
                duration,
                None,
                "backward_euler",
            )
        )
        print(rows[-1], flush=True)
    load = os.getloadavg()
    lines = [
        f"`python benchmarks/cloth_self.py --duration {duration:g}{' --quick' if args.quick else ''}`, "
        f"{time.strftime('%Y-%m-%d')}, threads {args.threads}, load average {load[0]:.2f} / {load[1]:.2f} / "
        f"{load[2]:.2f} (1 / 5 / 15 min) on {os.cpu_count()} cores",
        "",
        "| run | vertices | steps/s | time per step vs off | most contacts | most self-contacts | samples crossed |",
        "|---|---|---|---|---|---|---|",
    ]
    for on, off in ((rows[0], rows[1]), (rows[2], rows[3])):
        for row in (on, off):
            ratio = off["steps_per_second"] / row["steps_per_second"]
            crossed = f"{row['crossed']} of {row['samples']}"
            lines.append(
                f"| {row['label']} | {row['vertices']} | {row['steps_per_second']:.1f} | {ratio:.2f}× | "
                f"{row['max_contacts']} | {row['self_contacts']} | {crossed} |"
            )
    text = "\n".join(lines) + "\n"
    print(text)
    if not args.quick:
        os.makedirs(os.path.dirname(RESULTS), exist_ok=True)
        with open(RESULTS, "w", encoding="utf-8") as out:
            out.write(text)


if __name__ == "__main__":
    main()
