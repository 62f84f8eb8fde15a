"""Regenerate the README picture and the method guides' figures from real runs.

    python3 docs/make_figures.py            # writes docs/figures/ (a few minutes)
    python3 docs/make_figures.py --quick --out /tmp/figures   # short runs, to check the script

Every picture in README.md and docs/methods/*.md comes from here: each is drawn from a run of
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


def run(scene_name, method, seconds):
    scene = load_scene(scene_name, [f"simulation.method={method}"])
    return simulate(scene.model, method, scene.dt, seconds, scene.method_options.get(method, {}),
                    scene.integrator, record_every=4, scene_name=scene_name)


def guide_figures(out, scale):
    for method, scene, seconds, shown in GUIDES:
        result = run(scene, method, seconds * scale)
        folder = os.path.join(out, method)
        paths = write_plots(result.arrays, folder, title=f"{scene} with {method}")
        for name, path in paths.items():          # keep only what the guide shows
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


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "figures"))
    parser.add_argument("--quick", action="store_true", help="runs 20 times shorter, to test the script")
    args = parser.parse_args()
    os.makedirs(args.out, exist_ok=True)
    scale = 0.05 if args.quick else 1.0
    readme_picture(args.out, scale)
    guide_figures(args.out, scale)


if __name__ == "__main__":
    main()
