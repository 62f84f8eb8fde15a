"""Soak: 10⁵ steps of the 20-level pyramid with every method, at their defaults — no energy gain,
nothing falls (issue 20). A measurement, not a test: it takes about half an hour on 2 cores.

    python3 benchmarks/soak.py                       # 100,000 steps (dt = 1/240 s: 417 s simulated)
    python3 benchmarks/soak.py --steps 2000 --levels 8 --out /tmp/soak.md    # a smoke run

Each run goes through ``simulate`` with its health checks on (``contactlab.health``): a run
that gains energy beyond the scene's scale, speeds up past it or sinks through is stopped, and
its row says so. Beside that verdict the table gives the largest rise of the total energy
above its start, the largest box motion, steps per second, the thread setting and the load
of the machine before and after, and writes benchmarks/results/soak.md.
"""

import argparse
import os
import sys
import time

import numpy as np

from contactlab import SimulationDiverged, simulate
from contactlab.methods import AVAILABLE

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from peers import DT, contactlab_pyramid, machine, write_lines  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))


def soak(method, levels, steps, record_every):
    """One run's row: method, verdict, energy rise [J], largest box motion [m], steps/s, sweeps."""
    model = contactlab_pyramid(levels)
    started = time.perf_counter()
    try:
        run = simulate(model, method, DT, steps * DT, record_every=record_every)
        verdict = "ok"
    except SimulationDiverged as error:
        run, verdict = error.run, f"stopped: {error}"
    arrays = run.arrays
    energy = arrays["energy_kinetic"] + arrays["energy_potential"] + arrays["energy_elastic"]
    positions = arrays["body_position"]
    return {
        "method": method,
        "verdict": verdict,
        "steps": int(round(arrays["time"][-1] / DT)),
        "energy_rise": float(energy.max() - energy[0]),
        "energy_final": float(energy[-1] - energy[0]),
        "moved": float(np.linalg.norm(positions - positions[0], axis=2).max()),
        "steps_per_second": run.summary["steps_per_second"],
        "sweeps": run.summary["solver"]["mean_iterations"],
        "threads": run.summary["threads"],
        "wall": time.perf_counter() - started,
    }


def _described(info):
    return (
        f"{info['cpu']}, {info['cores']} cores; Python {info['python']}, NumPy {info['numpy']}, Numba "
        f"{info['numba']}, contactlab {info['contactlab']}; Numba threads {info['numba_threads']}"
    )


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=100_000)
    parser.add_argument("--levels", type=int, default=20)
    parser.add_argument("--methods", nargs="*", default=list(AVAILABLE))
    parser.add_argument("--out", default=os.path.join(HERE, "results", "soak.md"))
    args = parser.parse_args()
    load_before = os.getloadavg()[0]
    record_every = max(1, args.steps // 500)
    rows = []
    for method in args.methods:
        row = soak(method, args.levels, args.steps, record_every)
        rows.append(row)
        print(
            f"{method}: {row['verdict']}, energy rise {row['energy_rise']:.3g} J, moved {row['moved'] * 1000:.3g} "
            f"mm, {row['steps_per_second']:.0f} steps/s",
            flush=True,
        )
    load_after = os.getloadavg()[0]
    lines = [
        f"# Soak: {args.steps:,} steps of the {args.levels}-level pyramid, every method at its defaults",
        "",
        f"Written by `python benchmarks/soak.py` on {time.strftime('%Y-%m-%d')}: {_described(machine())}. "
        f"Load average (1 min) {load_before:.2f} before, {load_after:.2f} after. dt = 1/240 s, sampled every "
        f"{record_every} steps; health checks on.",
        "",
        "| method | verdict | steps | energy rise above the start (J) | energy at the end − start (J) | "
        "largest box motion (mm) | steps/s | sweeps per step | threads (steps at each count) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        lines.append(
            f"| {row['method']} | {row['verdict']} | {row['steps']:,} | {row['energy_rise']:.3g} | "
            f"{row['energy_final']:.3g} | {row['moved'] * 1000:.3g} | {row['steps_per_second']:.0f} | "
            f"{row['sweeps']:.1f} | {row['threads']['setting']} {row['threads']['steps_at']} |"
        )
    write_lines(args.out, lines)


if __name__ == "__main__":
    main()
