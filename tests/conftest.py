import numpy as np
import pytest

from contactlab import ModelBuilder


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


def ball_on_plane(restitution=0.0, friction=0.5, height=1.0, radius=0.1, mass=1.0, velocity=(0, 0, 0),
                  angular_velocity=(0, 0, 0)):
    """A sphere whose bottom is ``height`` above the plane z = 0, both of one material."""
    builder = ModelBuilder()
    builder.add_material("m", friction=friction, restitution=restitution)
    builder.add_body("sphere", radius=radius, mass=mass, position=(0, 0, radius + height), velocity=velocity,
                     angular_velocity=angular_velocity, material="m")
    builder.add_obstacle("plane", normal=(0, 0, 1), offset=0.0, material="m")
    return builder.finalize()


def random_rotations(rng, count):
    """Uniformly distributed rotation matrices (count, 3, 3), from unit quaternions."""
    from contactlab import rotations
    return rotations.to_matrix(rotations.normalize(rng.normal(size=(count, 4))))
