"""Make the synthetic cube tosses beside this file: tosses_NN.h5 (docs/validate.md).

No recorded data set could be fetched where this was written (no network), so these stand in
for one: contactlab's impulse method at dt = 1/1500 s, friction 0.3 and restitution 0.35 (not
the scene file's nominal 0.18 and 0.125), sampled at 150 Hz as a tracker would, with 0.5 mm of
position noise and 0.5 degrees of orientation noise, and no velocities (validate estimates
them). Each toss starts 10 to 20 cm up, turned at random, thrown at 0.5 to 1.5 m/s with a spin
of up to 8 rad/s, and lasts 0.8 s.

    python data/measured/make_tosses.py            # writes data/measured/toss_01.h5 ... toss_08.h5
"""

import os

import numpy as np

from contactlab.measured import write_synthetic
from contactlab.scene import load_scene

HERE = os.path.dirname(os.path.abspath(__file__))
TRUE = ["materials.0.friction=0.3", "materials.0.restitution=0.35"]
COUNT = 8


def main():
    rng = np.random.default_rng(40)
    for k in range(1, COUNT + 1):
        turn = rng.normal(size=4)
        turn /= np.linalg.norm(turn)
        speed, heading = rng.uniform(0.5, 1.5), rng.uniform(0, 2 * np.pi)
        settings = [
            *TRUE,
            "simulation.dt=0.0006666666666666666",
            "simulation.duration=0.8",
            f"bodies.0.position=[0.0, 0.0, {rng.uniform(0.1, 0.2)}]",
            f"bodies.0.orientation={[float(x) for x in turn]}",
            f"bodies.0.velocity={[float(speed * np.cos(heading)), float(speed * np.sin(heading)), rng.uniform(0.0, 1.0)]}",
            f"bodies.0.angular_velocity={[float(x) for x in rng.uniform(-8, 8, 3)]}",
        ]
        run = load_scene(os.path.join(HERE, "cube_toss.toml"), settings).simulate()
        path = os.path.join(HERE, f"toss_{k:02d}.h5")
        write_synthetic(path, run.arrays, every=10, position_noise=5e-4, angle_noise=np.radians(0.5), seed=k)
        print(path)


if __name__ == "__main__":
    main()
