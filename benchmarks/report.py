"""Turn benchmarks/results/results.json into benchmarks/results.md and PNG plots.

python benchmarks/report.py        # or: python benchmarks/peers.py --report-only
"""

import json
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))


def _fmt(value, digits=3):
    if value is None:
        return "–"
    if isinstance(value, float):
        if np.isnan(value):
            return "–"
        return f"{value:.{digits}g}"
    return str(value)


def _mm(value):
    return "–" if value is None else f"{1e3 * value:.2f}"


def _load(row):
    """The 1-minute load average(s) recorded with a row, or – for rows measured before loads were kept."""
    return "–".join(f"{value:.2f}" for value in row.get("load", [])) or "–"


def _threads_cell(row):
    """The threads a run stepped on: a peer's 1; contactlab's setting and how many steps ran on
    each thread count (``auto`` chooses as it goes), e.g. "auto: 1 × 19, 2 × 701"."""
    threads = row.get("threads")
    if row["engine"] != "contactlab":
        return "1"
    if not isinstance(threads, dict):
        return "–" if threads is None else str(threads)
    steps = ", ".join(f"{count} × {n}" for count, n in sorted(threads.get("steps_at", {}).items()))
    return f"{threads.get('setting')}: {steps}" if steps else str(threads.get("setting"))


def _runs(results, scene):
    return [(k, v) for k, v in sorted(results.get("runs", {}).items()) if v.get("scene") == scene]


def _rate(results, key):
    row = results.get("runs", {}).get(key)
    return None if row is None or "steps_per_second" not in row else row["steps_per_second"]


def scaling_fit(results):
    rows = [r for _, r in _runs(results, "scaling") if "ms_per_step" in r]
    rows.sort(key=lambda r: r["bodies"])
    if len(rows) < 2:
        return rows, None
    n = np.array([r["bodies"] for r in rows], float)
    t = np.array([r["ms_per_step"] for r in rows], float)
    exponent, log_c = np.polyfit(np.log(n), np.log(t), 1)
    return rows, (float(exponent), float(log_c))


def targets(results):
    """Lines of (target, measured, met?) for the issue's benchmark targets."""
    out = []
    runs = results.get("runs", {})
    ours, bullet, mj = (_rate(results, f"ball/{engine}") for engine in ("contactlab-impulse", "pybullet", "mujoco"))
    if ours and bullet and mj:
        out.append(
            (
                "ball: impulse ≥ MuJoCo's steps/s and ≥ ½ pybullet's",
                f"{ours / mj:.3f}× MuJoCo, {ours / bullet:.3f}× pybullet ({ours:,.0f} vs {mj:,.0f} and "
                f"{bullet:,.0f} steps/s)",
                "met" if ours >= mj and ours >= 0.5 * bullet else "NOT met",
            )
        )
    else:
        out.append(("ball: impulse ≥ MuJoCo and ≥ ½ pybullet", "not measured", "missing"))
    for scene in ("pile1000", "pile4000", "pyramid", "pyramid_touching", "pyramid3d"):  # issue 38's
        out.append(_against_pybullet(results, scene))
    out.append(_methods_target(results))
    out.append(_cold_start_target(runs.get("coldstart/contactlab")))
    threads = _threads(results)
    if threads:
        loaded = [row for row in threads["rows"] if row["load"] != "idle"]
        worst = min(loaded, key=lambda row: row["auto_over_one"])
        out.append(
            (
                "threads: with a busy core, the default setting ≥ one thread on every benchmark scene",
                f"auto / one thread ≥ {worst['auto_over_one']:.2f} (worst: {worst['scene']}) over "
                f"{len(loaded)} scenes; see results/threads.md",
                "met" if worst["auto_over_one"] >= 0.95 else "NOT met",
            )
        )
    else:
        out.append(("threads under load", "not measured (benchmarks/threads.py)", "missing"))
    _, fit = scaling_fit(results)
    if fit:
        sizes = [r["bodies"] for _, r in _runs(results, "scaling") if "ms_per_step" in r]
        out.append(
            (
                "scaling 1000–10000 spheres: time per step ≤ N^1.1",
                f"N^{fit[0]:.2f} over N = {min(sizes)}–{max(sizes)} ({len(sizes)} sizes)",
                "met" if fit[0] <= 1.1 and max(sizes) >= 10000 else "NOT met",
            )
        )
    else:
        out.append(("scaling ≤ N^1.1", "not measured", "missing"))
    pgs = runs.get("lcp/pgs")
    colored = [runs[f"lcp/{m}"] for m in ("redblack", "redblack_blocks") if f"lcp/{m}" in runs]
    if pgs and colored:
        cells, met = [], False
        for rb in colored:
            speedup = pgs["seconds"] / rb["seconds"]
            same = pgs["converged"] and rb["converged"] and rb["relative_difference"] < 1e-4
            met = met or (speedup >= 1.6 and same)
            cells.append(
                f"{rb['method']} {speedup:.2f}× ({pgs['seconds'] * 1e3:.0f} vs {rb['seconds'] * 1e3:.0f} ms, "
                f"{pgs['sweeps']} vs {rb['sweeps']} sweeps, relative λ difference {rb['relative_difference']:.1e})"
            )
        out.append(
            (
                "red-black sweeps ≥ 1.6× serial pgs on 2 cores, same converged answer",
                "; ".join(cells),
                "met" if met else "NOT met",
            )
        )
    else:
        out.append(("redblack ≥ 1.6× pgs", "not measured", "missing"))
    for n in (64, 128):
        mine = [_rate(results, f"cloth{n}/contactlab-{m}") for m in ("projection", "constraints")]
        peer = runs.get(f"cloth{n}/mujoco", {})
        if any(mine) and peer:
            theirs = f"{peer['steps_per_second']:.1f} steps/s" if "steps_per_second" in peer else peer.get("error")
            out.append(
                (
                    f"cloth {n}×{n}: report steps/s against MuJoCo",
                    f"projection {_fmt(mine[0])}, constraints {_fmt(mine[1])} steps/s; MuJoCo: {theirs}",
                    "reported",
                )
            )
        else:
            out.append((f"cloth {n}×{n}", "not measured", "missing"))
    return out


METHODS = ("constraints", "impulse", "projection", "penalty")


def _against_pybullet(results, scene):
    """Issue 38's target row of ``scene``: ``constraints`` at its defaults ≥ 5× pybullet's steps/s
    in every interleaved round (one, where there are none), with the piles' deepest overlap
    ≤ 1 mm and every pyramid box within 1 mm over 5 s."""
    runs = results.get("runs", {})
    ours, bullet = _rate(results, f"{scene}/contactlab-constraints"), _rate(results, f"{scene}/pybullet")
    if not (ours and bullet):
        return (f"{scene}: constraints ≥ 5× pybullet", "not measured", "missing")
    row = runs.get(f"{scene}/contactlab-constraints", {})
    paired = list(zip(row.get("round_rates", []), runs.get(f"{scene}/pybullet", {}).get("round_rates", [])))
    ratios = [a / b for a, b in paired] or [ours / bullet]
    rounds = f"; best of {len(paired)} interleaved rounds, each round " if len(paired) > 1 else ""
    rounds += ", ".join(f"{r:.2f}×" for r in ratios) if rounds else ""
    if scene.startswith("pile"):
        pen = row.get("max_penetration")
        accurate, claim, measure = pen is not None and pen <= 1e-3, "penetration ≤ 1 mm", f"penetration {_mm(pen)} mm"
    else:
        drift = row.get("drift")
        accurate = drift is not None and drift < 1e-3 and row.get("duration", 0) >= 5
        claim = "every box < 1 mm in 5 s"
        measure = f"largest box motion {_mm(drift)} mm in {row.get('duration')} s"
    return (
        f"{scene}: constraints at its defaults ≥ 5× pybullet in every round, {claim}",
        f"{ours / bullet:.2f}× ({ours:.1f} vs {bullet:.1f} steps/s, {_fmt(row.get('sweeps_per_step'))} sweeps "
        f"a step{rounds}); {measure}",
        "met" if min(ratios) >= 5 and accurate else "NOT met",
    )


def _methods_target(results):
    """(target, measured, status) of "every method runs compiled, reported on the pile and the
    pyramid": each method's steps/s on both scenes, or how it failed."""
    runs = results.get("runs", {})
    cells = []
    for scene in ("pile1000", "pyramid"):
        for method in METHODS:
            row = runs.get(f"{scene}/contactlab-{method}")
            if row is None:
                return ("every method on the pile and the pyramid", f"{scene} {method}: not measured", "missing")
            rate = row.get("steps_per_second")
            cells.append(f"{scene} {method} " + (f"{rate:.1f}" if rate else "failed (see its table)"))
    return ("penalty, projection, impulse and constraints on the pile and the pyramid", "; ".join(cells), "reported")


def _cold_start_target(row):
    """(target, measured, status) of the start-up targets from the ``coldstart`` row."""
    target = "first `contactlab demo` on an empty cache ≤ 15 s and says it compiles; second ≤ 3 s; import ≤ 0.5 s"
    if row is None:
        return (target, "not measured (peers.py --only coldstart)", "missing")
    ok = (
        row["first_returncode"] == 0
        and row["second_returncode"] == 0
        and row["first_says_compiling"]
        and not row["second_says_compiling"]
        and row["first_wall"] <= 15.0
        and row["second_wall"] <= 3.0
        and row["import_seconds"] <= 0.5
    )
    measured = (
        f"first {row['first_wall']:.1f} s wall ({row['first_cpu']:.1f} s CPU), "
        f"{'says' if row['first_says_compiling'] else 'does NOT say'} it compiles; second {row['second_wall']:.1f} s"
        f"{' (compiled again!)' if row['second_says_compiling'] else ''}; import {1e3 * row['import_seconds']:.1f} ms; "
        f"load {'–'.join(f'{x:.2f}' for x in row['load'])}"
    )
    return (target, measured, "met" if ok else "NOT met")


def _package_lines():
    """(lines of src/contactlab/methods, lines of src/contactlab): issue 36's size targets."""
    src = os.path.join(os.path.dirname(HERE), "src", "contactlab")

    def lines(folder):
        total = 0
        for root, _, names in os.walk(folder):
            for name in names:
                if name.endswith(".py"):
                    with open(os.path.join(root, name)) as stream:
                        total += sum(1 for _ in stream)
        return total

    return lines(os.path.join(src, "methods")), lines(src)


def issue36_targets(results):
    """Lines of (target, measured, status) for issue 36's targets (short runs, one process's many
    runs, the cold start, the code's size)."""
    runs = results.get("runs", {})
    out = []
    ours, theirs = runs.get("shortrun/contactlab"), runs.get("shortrun/mujoco")
    target = "720-step ball (impulse), second run in a fresh process ≥ MuJoCo's steps/s"
    if ours and theirs:
        second, first = ours["second"], ours["first"]
        out.append(
            (
                target,
                f"{second['steps_per_second'] / theirs['steps_per_second']:.2f}× MuJoCo "
                f"({second['steps_per_second']:,.0f} vs {theirs['steps_per_second']:,.0f} steps/s; compiled loop "
                f"{second['compiled_loop']}; first run on an empty cache {first['steps_per_second']:,.0f} steps/s, "
                f"compiled loop {first['compiled_loop']}, {first['process_wall']:.1f} s in all); load "
                f"{'–'.join(f'{x:.2f}' for x in ours['load'])}",
                "met" if second["steps_per_second"] >= theirs["steps_per_second"] else "NOT met",
            )
        )
    else:
        out.append((target, "not measured (peers.py --only shortruns)", "missing"))
    ours, theirs = runs.get("manyruns/contactlab"), runs.get("manyruns/mujoco")
    target = "200 such runs through simulate() in one process ≥ ½ MuJoCo's reset-and-step throughput"
    if ours and theirs:
        defaults, looped = ours["defaults"], ours["loop_compiled"]
        ratio = theirs["ms_per_run"] / defaults["ms_per_run"]
        out.append(
            (
                target,
                f"at the defaults on the short runs' cache {ratio:.3f}× ({defaults['ms_per_run']:.2f} vs "
                f"{theirs['ms_per_run']:.2f} ms a run, stepping: {defaults['stepping']}); once the loop is "
                f"compiled {theirs['ms_per_run'] / looped['ms_per_run']:.2f}× ({looped['ms_per_run']:.2f} ms a "
                f"run, stepping: {looped['stepping']}); load {'–'.join(f'{x:.2f}' for x in ours['load'])}",
                "met" if ratio >= 0.5 else "NOT met at the defaults",
            )
        )
    else:
        out.append((target, "not measured (peers.py --only shortruns)", "missing"))
    row = runs.get("coldstart/contactlab")
    target = "first `contactlab demo` on an empty cache ≤ 12 s, the second ≤ 2 s"
    if row:
        ok = row["first_wall"] <= 12.0 and row["second_wall"] <= 2.0
        out.append(
            (
                target,
                f"first {row['first_wall']:.1f} s wall ({row['first_cpu']:.1f} s CPU), second "
                f"{row['second_wall']:.1f} s",
                "met" if ok else "NOT met",
            )
        )
    else:
        out.append((target, "not measured (peers.py --only coldstart)", "missing"))
    methods, package = _package_lines()
    out.append(
        (
            "methods/ ≤ 3,600 lines; the package ≤ 27,700",
            f"methods/ {methods:,}; the package {package:,} (counted when this report was written)",
            "met" if methods <= 3600 and package <= 27700 else "NOT met",
        )
    )
    return out


def _threads(results):
    """benchmarks/results/threads.json (written by benchmarks/threads.py), or None."""
    path = os.path.join(HERE, "results", "threads.json")
    if not os.path.exists(path):
        return None
    with open(path) as stream:
        return json.load(stream)


def write_report(results, md_path, plot_dir):
    os.makedirs(plot_dir, exist_ok=True)
    m = results.get("machine", {})
    lines = ["# Benchmark results (generated by `benchmarks/peers.py`; do not edit by hand)", ""]
    lines.append(
        f"Mode: **{results.get('mode', '?')}** (durations in the tables). Machine: {m.get('cpu', '?')}, "
        f"{m.get('cores', '?')} cores; Python {m.get('python', '?')}, NumPy {m.get('numpy', '?')}, "
        f"SciPy {m.get('scipy', '?')}, Numba {m.get('numba', '?')}, contactlab {m.get('contactlab', '?')}, "
        f"pybullet {m.get('pybullet', 'not installed')}, MuJoCo {m.get('mujoco', 'not installed')}; "
        f"BLAS threads {m.get('blas_threads', '?')}, Numba threads {m.get('numba_threads', '?')}; "
        f"{m.get('date', '')}. dt = 1/240 s; settings: {results.get('settings_mode', 'matched 50 iterations')}."
    )
    lines += ["", "## Targets of issue 18", "", "| target | measured | status |", "|---|---|---|"]
    lines += [f"| {a} | {b} | {c} |" for a, b, c in targets(results)]
    lines += ["", "## Targets of issue 36", "", "| target | measured | status |", "|---|---|---|"]
    lines += [f"| {a} | {b} | {c} |" for a, b, c in issue36_targets(results)]

    header = (
        "| run | method | bodies | sim s | steps/s | × pybullet | × MuJoCo | max penetration mm | drift mm "
        "| sweeps per step | threads | load |"
    )
    rows = _runs(results, "ball")
    if rows:
        lines += [
            "",
            "## One ball bouncing (r = 5 cm, ε = 0.8, from 1 m): the per-step overhead",
            "",
            "Each engine's best of interleaved rounds (a run is milliseconds: one round says more about"
            " the machine's other work than about the engine); every round's rate and the 1-minute load"
            " average before and after the rounds beside it. MuJoCo has no restitution coefficient:"
            " contactlab.peers gives it the contact damping ratio at which its contact returns ε on average"
            " (docs/peers.md).",
            "",
            "| run | method | sim s | steps/s (best) | µs per step | every round, steps/s | load | "
            "first apex m (closed form) |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for _key, r in rows:
            rounds = ", ".join(f"{rate:,}" for rate in r.get("round_rates", []))
            load = _load(r)
            lines.append(
                f"| {r['engine']} | {r['method']} | {r['duration']} | {r['steps_per_second']:,.0f} | "
                f"{1e6 / r['steps_per_second']:.1f} | {rounds} | {load} | {_fmt(r.get('first_apex'), 4)} "
                f"({_fmt(r.get('expected_apex'), 4)}) |"
            )
    for scene, title in (
        ("pile1000", "Sphere pile, 1000"),
        ("pile4000", "Sphere pile, 4000 (taller column)"),
        ("pyramid", "Box pyramid, 20 levels (210 boxes)"),
    ):
        rows = _runs(results, scene)
        if not rows:
            continue
        bullet, mj = _rate(results, f"{scene}/pybullet"), _rate(results, f"{scene}/mujoco")
        extra = " boxes > 1 mm | boxes > 1 cm |" if scene == "pyramid" else ""
        lines += ["", f"## {title}", "", header + extra, "|---" * (12 + (2 if extra else 0)) + "|"]
        for _key, r in rows:
            if "error" in r:
                lines.append(f"| {r['engine']} | {r['method']} | failed: {r['error']} |" + " |" * (9 + bool(extra) * 2))
                continue
            rate = r["steps_per_second"]
            row = (
                f"| {r['engine']} | {r['method']} | {r.get('bodies')} | {r.get('duration')} | {rate:.1f} | "
                f"{_fmt(rate / bullet) if bullet else '–'} | {_fmt(rate / mj) if mj else '–'} | "
                f"{_mm(r.get('max_penetration'))} | {_mm(r.get('drift'))} | {_fmt(r.get('sweeps_per_step'))} | "
                f"{_threads_cell(r)} | {_load(r)} |"
            )
            if extra:
                row += f" {r.get('moved_over_1mm', '–')} | {r.get('moved_over_1cm', '–')} |"
            lines.append(row)
    for n in (64, 128):
        rows = _runs(results, f"cloth{n}")
        if not rows:
            continue
        mj = _rate(results, f"cloth{n}/mujoco")
        lines += [
            "",
            f"## Cloth drape, {n} × {n} vertices",
            "",
            "| run | method | sim s | steps/s | × MuJoCo | max penetration mm | lowest vertex z mm |",
            "|---|---|---|---|---|---|---|",
        ]
        for _key, r in rows:
            if "error" in r:
                said = r["error"] if r["method"] == "not run" else f"failed: {r['error']}"
                lines.append(f"| {r['engine']} | {r['method']} | {said} | | | | |")
                continue
            rate = r["steps_per_second"]
            lines.append(
                f"| {r['engine']} | {r['method']} | {r['duration']} | {rate:.1f} | "
                f"{_fmt(rate / mj) if mj else '–'} | {_mm(r['max_penetration'])} | "
                f"{_mm(r.get('lowest_vertex'))} |"
            )
    lines += _builtin_scenes(results)
    rows, fit = scaling_fit(results)
    if rows:
        lines += [
            "",
            "## Scaling: contactlab `constraints`, sphere pile widened with N",
            "",
            "| N | grid | sim s | steps/s | ms per step | max contacts |",
            "|---|---|---|---|---|---|",
        ]
        for r in rows:
            lines.append(
                f"| {r['bodies']} | {r['grid']}×{r['grid']} | {r['duration']} | "
                f"{r['steps_per_second']:.1f} | {r['ms_per_step']:.2f} | {r['max_contacts']} |"
            )
        if fit:
            lines.append(f"\nLog-log fit: time per step ∝ N^{fit[0]:.2f}.")
    lcp = [results.get("runs", {}).get(f"lcp/{m}") for m in ("pgs", "redblack", "redblack_blocks")]
    lcp = [r for r in lcp if r]
    if lcp and lcp[0]["method"] == "pgs":
        pgs = lcp[0]
        lines += [
            "",
            f"## Serial pgs vs red-black sweeps on one LCP ({pgs['source']}; {pgs['rows']} rows, "
            f"{pgs['nonzeros']} non-zeros, tol 1e-8, best of 3)",
            "",
            "| method | seconds | × pgs | sweeps | residual | converged | colors | λ relative to pgs's |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for r in lcp:
            lines.append(
                f"| {r['method']} | {r['seconds']:.4f} | {pgs['seconds'] / r['seconds']:.2f} | {r['sweeps']} | "
                f"{r['residual']:.2e} | {r['converged']} | {r['colors']} | {r.get('relative_difference', 0.0):.1e} |"
            )
    lines += ["", "Plots: `results/steps_per_second.png`, `results/penetration.png`, `results/scaling.png`.", ""]
    with open(md_path, "w") as f:
        f.write("\n".join(lines))
    plots(results, plot_dir)


def _builtin_scenes(results):
    """The built-in scenes' section: each engine's row as ``contactlab compare --peers`` reports
    it (steps/s, penetration, energy drift, the scene's expectations with their numbers)."""
    scenes = sorted({r["scene"] for r in results.get("runs", {}).values() if r.get("scene", "").startswith("builtin-")})
    if not scenes:
        return []
    lines = [
        "",
        "## Built-in scenes as `contactlab compare SCENE --peers pybullet,mujoco` runs them",
        "",
        "Each at its own dt and duration, sampled every step; contactlab at the scene's method and"
        " defaults, the peers through contactlab.peers (the comparison's own worlds); the measures and"
        " verdicts are the comparison's (contactlab.compare.measures, contactlab.closed_form).",
        "",
        "| scene | run | method | dt s | sim s | steps/s | × contactlab | max penetration mm | energy drift J "
        "| expectations | measured (expected) | threads | load |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for scene in scenes:
        rows = _runs(results, scene)
        ours = next((r["steps_per_second"] for _, r in rows if r["engine"] == "contactlab"), None)
        for _key, r in rows:
            said = "; ".join(
                f"{c['quantity']} {_fmt(c['measured'], 4)} ({_fmt(c['expected'], 4)})"
                f"{'' if c['passed'] is None else ' pass' if c['passed'] else ' FAIL'}"
                for c in r.get("checks", [])
            )
            rate, name = r["steps_per_second"], scene.removeprefix("builtin-")
            lines.append(
                f"| {name} | {r['engine']} | {r['method']} | {r['dt']:.4g} | {r['duration']} | {rate:,.0f} | "
                f"{_fmt(rate / ours) if ours else '–'} | {_fmt(1e3 * r['max_penetration'], 3)} | "
                f"{_fmt(r['energy_drift'], 3)} | {r['expectations']} | {said or '–'} | {_threads_cell(r)} | "
                f"{_load(r)} |"
            )
    return lines


def plots(results, plot_dir):
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib is not installed: no plots")
        return
    runs = [
        (k, r)
        for k, r in sorted(results.get("runs", {}).items())
        if r.get("scene") in ("ball", "pile1000", "pile4000", "pyramid", "cloth64", "cloth128")
        and "steps_per_second" in r
    ]
    if runs:
        scenes = sorted(
            {r["scene"] for _, r in runs},
            key=lambda s: ["ball", "pile1000", "pile4000", "pyramid", "cloth64", "cloth128"].index(s),
        )
        for quantity, fname, label, scale in (
            ("steps_per_second", "steps_per_second.png", "steps/s (log)", 1.0),
            ("max_penetration", "penetration.png", "max penetration [mm]", 1e3),
        ):
            fig, axes = plt.subplots(1, len(scenes), figsize=(3.6 * len(scenes), 4.2), squeeze=False)
            for ax, scene in zip(axes[0], scenes):
                rows = [
                    (r["engine"] + ("\n" + r["method"] if r["engine"] == "contactlab" else ""), r)
                    for _, r in runs
                    if r["scene"] == scene
                ]
                names = [n for n, _ in rows]
                values = [r.get(quantity, 0.0) * scale for _, r in rows]
                colors = [
                    "C0" if r["engine"] == "contactlab" else "C1" if r["engine"] == "pybullet" else "C2"
                    for _, r in rows
                ]
                ax.bar(range(len(values)), values, color=colors)
                ax.set_xticks(range(len(values)))
                ax.set_xticklabels(names, rotation=60, ha="right", fontsize=7)
                ax.set_title(scene)
                if quantity == "steps_per_second":
                    ax.set_yscale("log")
                ax.set_ylabel(label)
            fig.tight_layout()
            fig.savefig(os.path.join(plot_dir, fname), dpi=110)
            plt.close(fig)
    rows, fit = scaling_fit(results)
    if rows:
        n = np.array([r["bodies"] for r in rows], float)
        t = np.array([r["ms_per_step"] for r in rows], float)
        fig, ax = plt.subplots(figsize=(5, 4))
        ax.loglog(n, t, "o-", label="contactlab constraints")
        if fit:
            ax.loglog(n, np.exp(fit[1]) * n ** fit[0], "--", label=f"fit: N^{fit[0]:.2f}")
        ax.loglog(n, t[0] * (n / n[0]) ** 1.1, ":", color="gray", label="target bound N^1.1")
        ax.set_xlabel("spheres N")
        ax.set_ylabel("ms per step")
        ax.legend()
        ax.grid(True, which="both", alpha=0.3)
        fig.tight_layout()
        fig.savefig(os.path.join(plot_dir, "scaling.png"), dpi=110)
        plt.close(fig)


if __name__ == "__main__":
    path = sys.argv[1] if len(sys.argv) > 1 else os.path.join(HERE, "results", "results.json")
    with open(path) as f:
        write_report(json.load(f), os.path.join(HERE, "results.md"), os.path.join(HERE, "results"))
