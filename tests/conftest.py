import os
import re
import signal
import time
from pathlib import Path

import numpy as np
import pytest

from contactlab import ModelBuilder

# The commands the tests start compile their kernels, as they did before a cold first run could
# step as Python (contactlab.kernel_variants): their stderr and timings stay what the tests expect.
# tests/test_kernel_variants.py takes this away to test that choice.
os.environ.setdefault("CONTACTLAB_KERNELS", "compiled")

FCLIB = Path(__file__).resolve().parents[1] / "data" / "fclib"
"""The FCLIB-format problems kept in the repository (provenance and licence: data/fclib/README.md)."""
FCLIB_FILES = sorted(path.name for path in FCLIB.glob("*") if path.suffix in (".dat", ".hdf5"))


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


def ball_on_plane(
    restitution=0.0, friction=0.5, height=1.0, radius=0.1, mass=1.0, velocity=(0, 0, 0), angular_velocity=(0, 0, 0)
):
    """A sphere whose bottom is ``height`` above the plane z = 0, both of one material."""
    builder = ModelBuilder()
    builder.add_material("m", friction=friction, restitution=restitution)
    builder.add_body(
        "sphere",
        radius=radius,
        mass=mass,
        position=(0, 0, radius + height),
        velocity=velocity,
        angular_velocity=angular_velocity,
        material="m",
    )
    builder.add_obstacle("plane", normal=(0, 0, 1), offset=0.0, material="m")
    return builder.finalize()


def random_rotations(rng, count):
    """Uniformly distributed rotation matrices (count, 3, 3), from unit quaternions."""
    from contactlab import rotations

    return rotations.to_matrix(rotations.normalize(rng.normal(size=(count, 4))))


def cube_on_plane(angle_degrees=0.0, friction=0.5, mass=1.0, velocity=(0, 0, 0), sink=0.0, half=0.05):
    """A cube (half edge ``half`` [m]) resting flat on a plane tilted by ``angle`` about y, sunk
    ``sink`` [m] into it; both of one material with restitution 0. Returns (model, the unit
    vector down the slope)."""
    theta = np.radians(angle_degrees)
    normal = np.array([-np.sin(theta), 0.0, np.cos(theta)])
    builder = ModelBuilder()
    builder.add_material("m", friction=friction, restitution=0.0)
    builder.add_body(
        "box",
        half_extents=(half, half, half),
        mass=mass,
        position=normal * (half - sink),
        orientation=(np.cos(theta / 2), 0.0, -np.sin(theta / 2), 0.0),
        velocity=velocity,
        material="m",
    )
    builder.add_obstacle("plane", normal=normal, offset=0.0, material="m")
    return builder.finalize(), -np.array([np.cos(theta), 0.0, np.sin(theta)])


def frictional_contacts(rng, nc=40, bodies=25, regularization=1e-3):
    """A random W = J M⁻¹ Jᵀ (3 nc, 3 nc) of contacts between point masses, each contact with its
    own frame, plus ``regularization`` I; q pushing them together and sliding, μ in [0.2, 0.8]
    (drawn after W and q: a test that ignores μ sees the same W and q)."""
    J = np.zeros((3 * nc, 3 * bodies))
    for a in range(nc):
        i, j = rng.choice(bodies, 2, replace=False)
        frame = np.linalg.qr(rng.normal(size=(3, 3)))[0]
        J[3 * a : 3 * a + 3, 3 * i : 3 * i + 3] = frame.T
        J[3 * a : 3 * a + 3, 3 * j : 3 * j + 3] = -frame.T
    W = J @ J.T + regularization * np.eye(3 * nc)
    q = rng.normal(size=3 * nc)
    q[::3] = -np.abs(q[::3])
    return W, q, rng.uniform(0.2, 0.8, nc)


def box_pyramid(levels=20, size=0.1, gap=0.005, friction=0.6):
    """The benchmark's 2D pyramid (benchmarks/peers.py): level L (from 0) holds levels − L cubes
    of ``size`` [m], 1 kg, each resting exactly on the level below, ``gap`` [m] apart sideways."""
    from contactlab import ModelBuilder

    b = ModelBuilder()
    b.add_material("wood", friction=friction, restitution=0.0)
    for level in range(levels):
        n = levels - level
        for i in range(n):
            b.add_body(
                "box",
                half_extents=(size / 2,) * 3,
                mass=1.0,
                position=((i - (n - 1) / 2) * (size + gap), 0.0, size / 2 + size * level),
                material="wood",
            )
    b.add_obstacle("plane", normal=(0, 0, 1), material="wood")
    return b.finalize()


def box_column(count=8, size=0.1, friction=0.6):
    """``count`` cubes of ``size`` [m], 1 kg, stacked on the floor."""
    from contactlab import ModelBuilder

    b = ModelBuilder()
    b.add_material("wood", friction=friction, restitution=0.0)
    for i in range(count):
        b.add_body(
            "box", half_extents=(size / 2,) * 3, mass=1.0, position=(0.0, 0.0, size / 2 + size * i), material="wood"
        )
    b.add_obstacle("plane", normal=(0, 0, 1), material="wood")
    return b.finalize()


def interruptible():
    """A ``preexec_fn`` for a child process a test interrupts with SIGINT: Ctrl-C's default
    action restored in the child. A shell runs a background job with SIGINT ignored, and a child
    inherits that: a ``.ci/run`` started with ``&`` would otherwise send a signal the command
    line rightly ignores (as under nohup), and read exit 0 for 130."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def alive_in_group(group, seconds):
    """The processes of the process group ``group`` still running (zombies aside: an orphan's
    exit status waits for an init that reaps it) after waiting up to ``seconds`` for them."""
    deadline = time.monotonic() + seconds
    while True:
        alive = []
        for entry in os.listdir("/proc"):
            try:
                with open(f"/proc/{entry}/stat", encoding="ascii", errors="replace") as stream:
                    fields = stream.read().rsplit(")", 1)[1].split()
            except (OSError, IndexError):
                continue
            if entry.isdigit() and int(fields[2]) == group and fields[0] != "Z":
                alive.append(int(entry))
        if not alive or time.monotonic() > deadline:
            return alive
        time.sleep(0.1)


# contactlab.progress's plain line, printed every few seconds of long work where stderr is no terminal
PROGRESS_LINE = re.compile(r"^.+: [\d,]+/[\d,]+ \w+s(?: \(\d+ %\))? after \d+ s$")


def messages(stderr):
    """The lines of a command's ``stderr`` that say something: its progress lines left out."""
    return [line for line in stderr.splitlines() if not PROGRESS_LINE.match(line)]
