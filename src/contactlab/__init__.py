"""contactlab: contact resolution for physics simulation.

Build a model, step it with a method of the lecture, record it::

    from contactlab import ModelBuilder, simulate
    builder = ModelBuilder()
    builder.add_material("rubber", restitution=0.8)
    builder.add_body("sphere", radius=0.1, mass=1.0, position=(0, 0, 1.1), material="rubber")
    builder.add_obstacle("plane", normal=(0, 0, 1), offset=0.0, material="rubber")
    run = simulate(builder.finalize(), method="impulse", dt=0.001, duration=2.0)
"""

from .builder import ModelBuilder
from .collision import collide
from .contacts import Contacts
from .errors import InputError, SimulationDiverged
from .model import Model
from .simulation import Run, simulate
from .state import State
from .threads import set_threads

__all__ = ["ModelBuilder", "Model", "State", "Contacts", "collide", "simulate", "Run",
           "InputError", "SimulationDiverged", "set_threads"]
__version__ = "0.1.0"
