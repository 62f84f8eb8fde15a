"""Residual against sweeps on one step of a settled pile and pyramid (issue 38, item 1; a
measurement, not a test).

    python benchmarks/convergence.py                     # pile of 1000 spheres, 20-level pyramid
    python benchmarks/convergence.py --pile 400 --sweeps 150 --only pile

Each scene is built from the benchmark's own geometry (``benchmarks/peers.py``:
``contactlab_pile``, ``contactlab_pyramid``) and settled with ``constraints`` at its defaults
(dt = 1/240 s; the pile for ``--settle-pile`` s, by when it has landed and jammed, the pyramid
for ``--settle-pyramid`` s). Then the next step's contact problem is taken exactly as
``constraints``' step forms it (free velocities, contacts over the swept step, normal-row
targets, warm start from the carried impulses, the weight guess for new contacts) and solved
sweep by sweep by:

* the matrix-free sequential-impulse sweeps the methods run (``solve_sequential_impulses``), in
  several orders: the methods' own (``contact_order``: top to bottom, ties scrambled, then cut
  into ``split_into_slabs`` groups as ``loop_stages.solve`` does at ≥ 1000 contacts), plain top
  to bottom, bottom to top, the collision order, a random order, and the methods' order
  regrouped by a graph colouring of the contacts (bodies shared) keeping that order within each
  colour (what a coloured parallel sweep would do);
* on the assembled problem u = W r + q (``constraints.lcp_matrices``), ``nsgs`` and ``newton``
  (Coulomb friction, ``contactlab.lcp.solve_friction_contact``) and ``pgs`` and ``redblack``
  (the frictionless LCP of the normal rows, ``contactlab.lcp.solve_lcp``: another problem,
  drawn dashed).

Every solver starts from the same warm start. After each sweep (Newton: each Newton step) two
measures are recorded from its iterate r_k:

* the relative natural-map error of the friction problem (the Siconos/FCLIB measure,
  ``contactlab.lcp.natural_map_error``; for pgs/redblack the frictionless LCP's
  ‖min(λ, w)‖ / ‖c‖);
* the largest change of any contact's relative velocity over the sweep, max |W (r_k − r_{k−1})|
  [m/s]: the matrix-free solve's own stopping measure (tolerance 1e-7 m/s by default).

The numbers are deterministic (no clock): the machine's load does not change them. A sweep is
continued from the last one's impulses (u rebuilt from v* and the impulses each time), which
equals one uninterrupted solve up to rounding: checked against ``solve_sequential_impulses``'
own last change at the end of every matrix-free curve.

For item 2 of the issue the per-contact velocity change of the methods' own order over the
sweep at which the method stops is kept with each contact's height, its bodies' contact
count and whether it was carried from the last step (warm) or is new.

Results: ``benchmarks/results/convergence.json`` and, in ``--figures`` (default
benchmarks/results; ``docs/make_figures.py`` writes the constraints guide's with it),
``convergence_pile.png`` / ``convergence_pyramid.png`` (residual vs sweeps) and
``convergence_pile_contacts.png`` (where the last sweeps' changes are).
"""

import argparse
import json
import os
import sys
import time

from pinning import pin_threads  # the script's own folder is on sys.path

pin_threads(sys.argv)

import numpy as np  # noqa: E402
from peers import DT, contactlab_pile, contactlab_pyramid  # noqa: E402

from contactlab import simulate  # noqa: E402
from contactlab.contacts import jacobian, values_carried  # noqa: E402
from contactlab.dynamics.generalized import inverse_mass_matrix, stack  # noqa: E402
from contactlab.dynamics.integrators import free_velocities  # noqa: E402
from contactlab.lcp import color_contacts, natural_map_error, solve_friction_contact, solve_lcp  # noqa: E402
from contactlab.methods.constraints import Options, SystemInverse, lcp_matrices, normal_row_targets  # noqa: E402
from contactlab.methods.loop_stages import build_rows, loop_inputs, loop_settings  # noqa: E402
from contactlab.methods.sequential import (  # noqa: E402
    PARALLEL_MIN_CONTACTS,
    SWEEP_GROUPS,
    contact_order,
    solve_sequential_impulses,
    split_into_slabs,
)
from contactlab.methods.velocity_level import predict_positions, swept_contacts, warm_impulses  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
RESULTS_DIR = os.path.join(HERE, "results")
TINY = 1e-300  # a tolerance no sweep reaches: every solver runs the sweeps it is given


def settle(model, duration):
    """The State after ``duration`` s of ``constraints`` at its defaults, with its summary."""
    run = simulate(model, "constraints", DT, duration, {}, record_every=10**9, compiled_loop=True)
    return run.state, run.summary


def capture(model, state, options):
    """The next step's contact problem as ``constraints``' step forms it (velocity formulation,
    explicit bodies): a dict of the rows, targets, warm start, the methods' order, v*, the
    assembled W, q and the contacts with their facts (height, contacts per body, warm or new)."""
    h = DT
    free = free_velocities(model, state, h, "symplectic_euler")
    v_free = np.array(stack(*free), dtype=float)
    _, _, sweep = predict_positions(model, state, free, "symplectic_euler", h)
    contacts, _ = swept_contacts(model, state, options, sweep)
    arrays, motion, rotation, carried = loop_inputs(model, state, "constraints")
    settings = loop_settings(model, "constraints", options, h)
    found = contacts.arrays()
    rows = build_rows(arrays, found, motion, rotation)
    target, _ = normal_row_targets(model, state, contacts, rows, v_free, h, options)
    warm = warm_impulses(arrays, settings, found, motion, carried[0], carried[1])
    _, warm_found = values_carried(carried[0], carried[1], contacts.feature_id)
    order = contact_order(found.point, found.feature_id, arrays.gravity)
    J = jacobian(contacts, state.body_position, model.body_count, model.particle_count)
    targets = np.zeros((contacts.count, 3))
    targets[:, 0] = target
    W, q = lcp_matrices(
        J, SystemInverse(inverse_mass=inverse_mass_matrix(model, state.body_orientation)), v_free, targets.ravel()
    )
    per_body = np.bincount(
        np.concatenate([contacts.body_a[contacts.body_a >= 0], contacts.body_b[contacts.body_b >= 0]]),
        minlength=model.body_count,
    )
    sides = np.stack([contacts.body_a, contacts.body_b], axis=1)
    busiest = np.max(np.where(sides >= 0, per_body[np.maximum(sides, 0)], 0), axis=1)
    return dict(
        rows=rows,
        found=found,
        motion=motion,
        target=target,
        warm=warm,
        order=order,
        v_free=v_free,
        W=W,
        q=q,
        friction=np.asarray(contacts.friction, dtype=float),
        height=np.asarray(contacts.point[:, 2], dtype=float),
        busiest=busiest,
        carried=np.asarray(warm_found, dtype=bool),
        dynamic_pair=(contacts.body_a >= 0) & (contacts.body_b >= 0),
        iterations=settings.iterations,
        tolerance=settings.tolerance,
    )


def orders(problem, seed=0):
    """The matrix-free sweep orders measured: name → (order (C,), starts or None)."""
    rows, found, motion = problem["rows"], problem["found"], problem["motion"]
    C = len(problem["order"])
    methods = problem["order"]
    out = {}
    if C >= PARALLEL_MIN_CONTACTS:  # as loop_stages.solve groups it (the same numbers on any thread count)
        positions = (motion.body_position, motion.particle_position)
        grouped, _ = split_into_slabs(methods, found.point, rows, positions, SWEEP_GROUPS)
        out["methods' order (top down, 2 slabs)"] = grouped
    out["top down" if C >= PARALLEL_MIN_CONTACTS else "methods' order (top down)"] = methods
    out["bottom up"] = methods[::-1].copy()
    out["collision order"] = np.arange(C)
    out["random"] = np.random.default_rng(seed).permutation(C)
    sides = [[b for b in (a, bb) if b >= 0] for a, bb in zip(found.body_a, found.body_b)]
    colors = color_contacts(sides, rows.body_inverse_mass.shape[0])
    out[f"coloured ({colors.max() + 1} colours), top down within"] = methods[np.argsort(colors[methods], kind="stable")]
    return out


def sweeps_matrix_free(problem, order, sweeps):
    """The matrix-free sweeps in ``order``, one at a time: (natural-map errors, velocity changes,
    impulses after each sweep (list), the continuous solve's own last change)."""
    rows, friction, target, W, q = (problem[k] for k in ("rows", "friction", "target", "W", "q"))
    impulses = problem["warm"].copy()
    errors, changes, history = [], [], [impulses]
    for _ in range(sweeps):
        u = problem["v_free"].copy()
        impulses, _, change = solve_sequential_impulses(rows, friction, target, u, (1, 0.0), impulses, (order, None))
        errors.append(natural_map_error(W, q, friction, impulses.ravel()))
        changes.append(change)
        history.append(impulses)
    u = problem["v_free"].copy()
    _, _, whole = solve_sequential_impulses(
        rows, friction, target, u, (sweeps, 0.0), problem["warm"].copy(), (order, None)
    )
    return errors, changes, history, whole


def velocity_change(W, before, after):
    return float(np.max(np.abs(W @ (after.ravel() - before.ravel())))) if before.size else 0.0


def sweeps_assembled(problem, solver, sweeps):
    """``solver`` on the assembled problem from the warm start, one sweep after the other
    (``sweeps`` of them); newton: ``sweeps`` is a list of step counts, each replayed from the
    warm start (its line search keeps state between steps). Returns (errors, velocity changes
    — newton's between the listed step counts)."""
    W, q, friction, warm = problem["W"], problem["q"], problem["friction"], problem["warm"]
    errors, changes = [], []
    if solver in ("pgs", "redblack"):
        normal = np.arange(0, W.shape[0], 3)
        B, c = W[normal][:, normal], -q[normal]
        lam = np.maximum(warm[:, 0], 0.0)
        scale = max(float(np.linalg.norm(c)), 1e-300)
        for _ in range(sweeps):
            result = solve_lcp(B, c, method=solver, tol=TINY, max_iterations=1, warm_start=lam)
            changes.append(velocity_change(B, lam, result.lam))
            lam = result.lam
            errors.append(result.residual / scale)
        return errors, changes
    r = warm.ravel().copy()
    if solver == "newton":  # replayed from the warm start for each step count (a factorization a step)
        for steps in sweeps:
            result = solve_friction_contact(
                W, q, friction, method="newton", tol=TINY, max_iterations=steps, r0=warm.ravel()
            )
            changes.append(velocity_change(W, r, result.r))
            r = result.r
            errors.append(natural_map_error(W, q, friction, r))
        return errors, changes
    for _ in range(sweeps):
        result = solve_friction_contact(W, q, friction, method=solver, tol=TINY, max_iterations=1, r0=r)
        changes.append(velocity_change(W, r, result.r))
        r = result.r
        errors.append(natural_map_error(W, q, friction, r))
    return errors, changes


def contact_facts(problem, history, stop):
    """Per contact: |J Δu| over sweep ``stop`` of the methods' order (the largest of its three
    rows) [m/s], with its height, its busiest body's contact count, warm or new."""
    W = problem["W"]
    delta = np.abs(W @ (history[stop].ravel() - history[stop - 1].ravel())).reshape(-1, 3).max(axis=1)
    return delta


def plot_scene(name, label, curves, tolerance, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(13, 5))
    for solver, curve in curves.items():
        style = "--" if solver in ("pgs", "redblack") else ("o-" if solver == "newton" else "-")
        sweeps = curve["sweeps"]
        axes[0].semilogy(sweeps, np.maximum(curve["error"], 1e-17), style, label=solver)
        axes[1].semilogy(sweeps, np.maximum(curve["change"], 1e-17), style, label=solver)
    axes[0].set_title(f"{label}: natural-map error (relative)")
    axes[1].set_title(f"{label}: largest contact velocity change of a sweep [m/s]")
    axes[1].axhline(tolerance, color="k", lw=0.8, ls=":")
    axes[1].text(1, tolerance * 1.3, f"matrix-free tolerance {tolerance:g} m/s", fontsize=8)
    for ax in axes:
        ax.set_xlabel("sweeps (newton: Newton steps)")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_contacts(label, problem, delta, stop, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    carried = problem["carried"]
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.5))
    floor = max(float(delta[delta > 0].min()) if np.any(delta > 0) else 1e-17, 1e-17)
    shown = np.maximum(delta, floor)
    sliding = problem["sliding"]
    kinds = (
        (carried & ~sliding, "carried, sticking", "tab:blue"),
        (carried & sliding, "carried, at the cone's edge", "tab:orange"),
        (~carried, "new (weight guess)", "tab:red"),
    )
    for mask, name, colour in kinds:
        axes[0].scatter(shown[mask], problem["height"][mask], s=4, c=colour, label=f"{name}: {mask.sum()}")
    axes[0].set_xscale("log")
    axes[0].set_xlabel(f"|J Δu| over sweep {stop} [m/s]")
    axes[0].set_ylabel("contact height [m]")
    axes[0].legend(fontsize=8)
    counts = np.unique(problem["busiest"])
    data = [shown[problem["busiest"] == k] for k in counts]
    axes[1].boxplot(data, tick_labels=[str(k) for k in counts], showfliers=False)
    axes[1].set_yscale("log")
    axes[1].set_xlabel("contacts of the contact's busiest body")
    axes[1].set_ylabel(f"|J Δu| over sweep {stop} [m/s]")
    ordered = np.sort(delta)[::-1]
    share = np.cumsum(ordered**2) / max(float(np.sum(ordered**2)), 1e-300)
    axes[2].semilogx(np.arange(1, len(ordered) + 1) / len(ordered), share)
    axes[2].set_xlabel("fraction of contacts (largest change first)")
    axes[2].set_ylabel("share of Σ |J Δu|²")
    axes[2].grid(True, which="both", alpha=0.3)
    fig.suptitle(f"{label}: where the change of sweep {stop} is (methods' order)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run_scene(name, label, model, duration, sweeps, newton_steps, assembled, figures=RESULTS_DIR):
    t0 = time.perf_counter()
    state, summary = settle(model, duration)
    mean = summary["solver"]["mean_iterations"]
    print(f"{label}: settled {duration} s in {time.perf_counter() - t0:.0f} s, mean sweeps {mean:.1f}")
    options = Options()
    problem = capture(model, state, options)
    C = len(problem["order"])
    print(f"  {C} contacts, {int((~problem['carried']).sum())} new")
    curves, check = {}, {}
    methods_history, methods_name = None, None
    for order_name, order in orders(problem).items():
        errors, changes, history, whole = sweeps_matrix_free(problem, order, sweeps)
        curves[order_name] = dict(error=errors, change=changes, sweeps=list(range(1, sweeps + 1)))
        check[order_name] = dict(sweep_by_sweep=changes[-1], one_solve=whole)
        if methods_history is None:
            methods_history, methods_name = history, order_name
        reached = next((k + 1 for k, c in enumerate(changes) if c <= problem["tolerance"]), None)
        print(
            f"  {order_name}: tolerance reached at sweep {reached}, error {errors[-1]:.2e}, "
            f"last change {changes[-1]:.2e} (one solve: {whole:.2e})"
        )
    for solver in assembled:
        t1 = time.perf_counter()
        n = list(newton_steps) if solver == "newton" else sweeps
        errors, changes = sweeps_assembled(problem, solver, n)
        curves[solver] = dict(error=errors, change=changes, sweeps=n if solver == "newton" else list(range(1, n + 1)))
        print(f"  {solver}: error {errors[-1]:.2e} after {n} ({time.perf_counter() - t1:.0f} s)")
    methods = curves[methods_name]["change"]  # the sweep the method stops at: its tolerance, or its cap
    cap = min(problem["iterations"], len(methods))
    stop = next((k + 1 for k, c in enumerate(methods[:cap]) if c <= problem["tolerance"]), cap)
    delta = contact_facts(problem, methods_history, stop)
    r = methods_history[stop].reshape(-1, 3)
    sliding = np.hypot(r[:, 1], r[:, 2]) >= 0.999 * problem["friction"] * r[:, 0]
    problem["sliding"] = sliding & (r[:, 0] > 0)
    kind = name.rstrip("0123456789")  # pile, pyramid: the figures' names hold no size, so the docs' links stay
    plot_scene(name, label, curves, problem["tolerance"], os.path.join(figures, f"convergence_{kind}.png"))
    plot_contacts(label, problem, delta, stop, os.path.join(figures, f"convergence_{kind}_contacts.png"))
    top = np.argsort(delta)[::-1][: max(1, C // 100)]
    facts = dict(
        contacts=C,
        new=int((~problem["carried"]).sum()),
        stop_sweep=stop,
        mean_sweeps_while_settling=summary["solver"]["mean_iterations"],
        top_percent=dict(
            count=len(top),
            new=int((~problem["carried"][top]).sum()),
            dynamic_pairs=int(problem["dynamic_pair"][top].sum()),
            median_height=float(np.median(problem["height"][top])),
            median_busiest=float(np.median(problem["busiest"][top])),
            sliding=int(problem["sliding"][top].sum()),
        ),
        all_contacts=dict(
            dynamic_pairs=int(problem["dynamic_pair"].sum()),
            median_height=float(np.median(problem["height"])),
            median_busiest=float(np.median(problem["busiest"])),
            sliding=int(problem["sliding"].sum()),
        ),
        change_by_sliding=dict(
            sliding_median=float(np.median(delta[problem["sliding"]])) if np.any(problem["sliding"]) else None,
            sticking_median=float(np.median(delta[~problem["sliding"]])) if np.any(~problem["sliding"]) else None,
        ),
        change_by_new=dict(
            new_median=float(np.median(delta[~problem["carried"]])) if np.any(~problem["carried"]) else None,
            carried_median=float(np.median(delta[problem["carried"]])) if np.any(problem["carried"]) else None,
        ),
    )
    return dict(label=label, settle=duration, curves=curves, check=check, facts=facts)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pile", type=int, default=1000, help="spheres in the pile (default 1000)")
    parser.add_argument("--levels", type=int, default=20, help="levels of the pyramid (default 20)")
    parser.add_argument("--settle-pile", type=float, default=1.5, help="s of settling before the pile's step")
    parser.add_argument("--settle-pyramid", type=float, default=1.0, help="s of settling before the pyramid's step")
    parser.add_argument("--sweeps", type=int, default=150, help="sweeps recorded per solver")
    parser.add_argument("--newton-steps", type=int, nargs="*", default=(1, 2, 4, 8), help="Newton step counts recorded")
    parser.add_argument("--only", nargs="*", choices=("pile", "pyramid"), default=("pile", "pyramid"))
    parser.add_argument("--assembled", nargs="*", default=("nsgs", "pgs", "redblack", "newton"))
    parser.add_argument("--numba-threads", type=int, default=2, help="(pinned before NumPy loads)")
    parser.add_argument(
        "--figures", default=RESULTS_DIR, help="folder of the PNGs (docs/make_figures.py: docs/figures/constraints)"
    )
    parser.add_argument("--results", default=RESULTS_DIR, help="folder of convergence.json (merged run by run)")
    args = parser.parse_args(argv)
    os.makedirs(args.results, exist_ok=True)
    os.makedirs(args.figures, exist_ok=True)
    path = os.path.join(args.results, "convergence.json")
    results = {}
    if os.path.exists(path):
        with open(path) as f:
            results = json.load(f)
    if "pile" in args.only:
        model, _ = contactlab_pile(args.pile)
        key = f"pile{args.pile}"
        results[key] = run_scene(
            key,
            f"pile of {args.pile} spheres",
            model,
            args.settle_pile,
            args.sweeps,
            args.newton_steps,
            args.assembled,
            args.figures,
        )
    if "pyramid" in args.only:
        key = f"pyramid{args.levels}"
        results[key] = run_scene(
            key,
            f"{args.levels}-level pyramid",
            contactlab_pyramid(args.levels),
            args.settle_pyramid,
            args.sweeps,
            args.newton_steps,
            args.assembled,
            args.figures,
        )
    with open(path, "w") as f:
        json.dump(results, f, indent=1)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
