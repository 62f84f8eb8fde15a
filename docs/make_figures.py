"""Regenerate the README picture and the method guides' figures from real runs.

    python3 docs/make_figures.py            # writes docs/figures/ (a few minutes)
    python3 docs/make_figures.py --quick --out /tmp/figures   # short runs, to check the script

Every picture in README.md, docs/methods/*.md and docs/viewer.md comes from here: each is drawn from a run of
a built-in scene with the settings below, so running this again after a change to a method
shows its effect in the documentation.
"""

import argparse
import os

import numpy as np
from PIL import Image

from contactlab.plots import write_plots
from contactlab.render import still
from contactlab.scene import load_scene
from contactlab.simulation import simulate

# (method, scene, seconds simulated, the plots its guide shows): chosen to show each method's
# character — penalty's soft, springy contact; projection holding a cloth; impulses at rest in
# a stack after impacts; hard constraints and their solver residual on a pyramid
GUIDES = [
    ("penalty", "bouncing_ball", 3.0, ("penetration", "energy")),
    ("projection", "cloth_drape", 3.0, ("penetration", "energy")),
    ("impulse", "box_stack", 3.0, ("penetration", "residual")),
    ("constraints", "box_pyramid", 3.0, ("penetration", "residual")),
]
# the README picture: one still per method of the same scene, side by side
README_SCENE, README_SECONDS = "cloth_drape", 2.5
README_METHODS = ("projection", "constraints")


def run(scene_name, method, seconds, overrides=()):
    scene = load_scene(scene_name, [f"simulation.method={method}", *overrides])
    return simulate(
        scene.model,
        method,
        scene.dt,
        seconds,
        scene.options.get(method),
        scene.integrator,
        record_every=4,
        scene_name=scene_name,
    )


def guide_figures(out, scale):
    for method, scene, seconds, shown in GUIDES:
        result = run(scene, method, seconds * scale)
        folder = os.path.join(out, method)
        paths = write_plots(result.arrays, folder, title=f"{scene} with {method}")
        for name, path in paths.items():  # keep only what the guide shows
            if name not in shown:
                os.unlink(path)
        still(result.arrays, os.path.join(folder, "still.png"), title=f"{scene} — {method}")
        print(f"{method}: {scene} for {seconds * scale:g} s → {folder}")


def readme_picture(out, scale):
    pictures = []
    for method in README_METHODS:
        result = run(README_SCENE, method, README_SECONDS * scale)
        path = os.path.join(out, f"readme-{method}.png")
        still(result.arrays, path, title=f"{README_SCENE} — {method}, t = {README_SECONDS * scale:g} s")
        pictures.append(np.asarray(Image.open(path).convert("RGB")))
        os.unlink(path)
    Image.fromarray(np.concatenate(pictures, axis=1)).save(os.path.join(out, "readme.png"))
    print(f"README picture → {os.path.join(out, 'readme.png')}")


# cloth self-contact (docs/collision.md): the cloth_fold strip folding as it piles up, with and without it
FOLD_SECONDS = 0.45


def cloth_fold_figure(out, scale):
    """docs/figures/cloth_fold.png: the built-in cloth_fold strip after FOLD_SECONDS with
    projection, self-contact on (left) and off (right), side by side, seen from low down."""
    pictures = []
    for on in ("true", "false"):
        result = run("cloth_fold", "projection", FOLD_SECONDS * scale, [f"cloth[0].self_collision={on}"])
        path = os.path.join(out, f"cloth_fold-{on}.png")
        title = f"cloth_fold — self_collision = {on}, t = {FOLD_SECONDS * scale:g} s"
        still(result.arrays, path, elevation=10.0, azimuth=-20.0, title=title)
        pictures.append(np.asarray(Image.open(path).convert("RGB")))
        os.unlink(path)
    Image.fromarray(np.concatenate(pictures, axis=1)).save(os.path.join(out, "cloth_fold.png"))
    print(f"cloth self-contact → {os.path.join(out, 'cloth_fold.png')}")


# penalty's price: how far the top of an 8-box stack sinks against the contact stiffness k
SINKING_STIFFNESSES = (3e3, 1e4, 3e4, 1e5, 3e5, 1e6)  # N/m
SINKING_BOXES, SINKING_DT, SINKING_SECONDS = 8, 1 / 240, 3.0


def penalty_sinking(out, scale):
    """docs/figures/penalty/sinking.png: the top box's sinking once settled, for each k and for
    "auto", against the closed form Σ_i (i m g / 4) / k of four springs under each of 8 levels."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from contactlab import ModelBuilder

    def stack():
        b = ModelBuilder()
        b.add_material("wood", friction=0.6, restitution=0.0)
        for i in range(SINKING_BOXES):
            b.add_body("box", half_extents=(0.05,) * 3, mass=1.0, position=(0, 0, 0.05 + 0.1 * i), material="wood")
        b.add_obstacle("plane", normal=(0, 0, 1), material="wood")
        return b.finalize()

    def sunk(options):  # the mean over the last third: a soft, explicit stack still rocks
        model = stack()
        result = simulate(model, "penalty", SINKING_DT, SINKING_SECONDS * scale, options, record_every=6)
        top = result.arrays["body_position"][:, -1, 2]
        return model.state().body_position[-1, 2] - top[2 * len(top) // 3 :].mean()

    g = 9.81
    measured = [sunk({"stiffness": k}) for k in SINKING_STIFFNESSES]
    auto = sunk({})
    ks = np.geomspace(SINKING_STIFFNESSES[0], SINKING_STIFFNESSES[-1], 50)
    figure, axes = plt.subplots(figsize=(6.4, 4.2), layout="constrained")
    levels = SINKING_BOXES * (SINKING_BOXES + 1) / 2
    axes.loglog(ks, 1000 * levels * g / (4 * ks), color="0.6", label="closed form Σ i m g / (4 k)")
    axes.loglog(SINKING_STIFFNESSES, 1000 * np.array(measured), "o", label="penalty, stiffness = k")
    axes.axhline(
        1000 * auto,
        color="C1",
        linestyle="--",
        label=f'stiffness = "auto" (each contact\'s load / 0.3 mm): {1000 * auto:.2g} mm',
    )
    axes.set_xlabel("contact stiffness k [N/m]")
    axes.set_ylabel("top box sunk [mm]")
    axes.set_title(
        f"{SINKING_BOXES}-box stack, 1 kg boxes, dt = 1/240 s, mean over the last third of {SINKING_SECONDS * scale:g} s"
    )
    axes.legend()
    path = os.path.join(out, "penalty", "sinking.png")
    os.makedirs(os.path.dirname(path), exist_ok=True)
    figure.savefig(path, dpi=110)
    plt.close(figure)
    print(f"penalty sinking against k → {path}")


# the viewer's picture (docs/viewer.md): the pyramid under hard constraints, contacts and forces shown
VIEWER_SCENE, VIEWER_METHOD, VIEWER_SECONDS = "box_pyramid", "constraints", 1.0
NOTICE_WIDTH = 320  # px: the left strip of the page where the browser's "software WebGL" notice sits


def viewer_picture(out, scale):
    """docs/figures/viewer.png: the viewer in headless Chromium (contactlab.browser), its
    contact points and force arrows on, at the end of the run; skipped without Chromium."""
    from contactlab import browser
    from contactlab.viewer import view

    if browser.chromium() is None:
        print("viewer picture skipped: no Chromium on PATH (apt-get install chromium)")
        return
    scene = load_scene(VIEWER_SCENE, [f"simulation.method={VIEWER_METHOD}"])
    result = simulate(
        scene.model,
        VIEWER_METHOD,
        scene.dt,
        VIEWER_SECONDS * scale,
        scene.options.get(VIEWER_METHOD),
        scene.integrator,
        scene_name=VIEWER_SCENE,
    )
    shown = view(result)
    try:
        for toggle in ("points", "forces"):
            shown.gui[toggle].value = True
        shown.show_time(shown.end)
        path = os.path.join(out, "viewer.png")
        with browser.Page(shown.url, width=1100, height=760) as page:
            page.wait_for(
                path,
                lambda p: (
                    (browser.coloured(browser.scene_part(p)) > 0.02)
                    & ((p[..., 0] > 0.7) & (p[..., 1] < 0.3) & (p[..., 2] < 0.3)).any()
                ),
                what="the viewer",
            )
    finally:
        shown.stop()
    picture = Image.open(path).convert("RGB")  # the page's viewport: the window less its frame
    picture.crop((NOTICE_WIDTH, 0, *picture.size)).save(path)
    print(f"viewer picture → {path}")


def convergence_figures(out, scale):
    """The constraints guide's residual-against-sweeps figures: ``benchmarks/convergence.py``
    (its own process, which pins the threads before NumPy loads) on the benchmark's 1000-sphere
    pile and 20-level pyramid; at a small scale a 100-sphere pile and a 5-level pyramid, briefly
    settled, to test the script."""
    import subprocess
    import sys

    script = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "benchmarks", "convergence.py")
    folder = os.path.join(out, "constraints")
    small = ["--pile", "100", "--levels", "5", "--settle-pile", "0.2", "--settle-pyramid", "0.1", "--sweeps", "10"]
    # a test's short runs keep their numbers beside their figures, not in benchmarks/results
    quick = [*small, "--newton-steps", "1", "--assembled", "nsgs", "--results", folder] if scale < 1.0 else []
    subprocess.run([sys.executable, script, "--figures", folder, *quick], check=True)
    print(f"constraints: residual against sweeps → {folder}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "figures"))
    parser.add_argument("--quick", action="store_true", help="runs 20 times shorter, to test the script")
    args = parser.parse_args()
    os.makedirs(args.out, exist_ok=True)
    scale = 0.05 if args.quick else 1.0
    readme_picture(args.out, scale)
    guide_figures(args.out, scale)
    cloth_fold_figure(args.out, scale)
    penalty_sinking(args.out, scale)
    viewer_picture(args.out, scale)
    convergence_figures(args.out, scale)


if __name__ == "__main__":
    main()
