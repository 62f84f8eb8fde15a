"""contactlab: contact resolution for physics simulation.

Build a model, step it with a method of the lecture, record it::

    from contactlab import ModelBuilder, simulate
    builder = ModelBuilder()
    builder.add_material("rubber", restitution=0.8)
    builder.add_body("sphere", radius=0.1, mass=1.0, position=(0, 0, 1.1), material="rubber")
    builder.add_obstacle("plane", normal=(0, 0, 1), offset=0.0, material="rubber")
    run = simulate(builder.finalize(), method="impulse", dt=0.001, duration=2.0)
"""

import sys
from importlib import import_module
from typing import Any

from .errors import InputError, SimulationDiverged

if "IPython" in sys.modules:  # in IPython or a notebook: a Model and a Run show as HTML
    from .notebook import register as _register_html

    _register_html()

# the rest is imported on first use (PEP 562), so that ``python -m contactlab`` and the
# ``contactlab`` command install their signal handlers before Numba and NumPy load
_LAZY = {
    "ModelBuilder": "builder",
    "collide": "collision",
    "Contacts": "contacts",
    "Model": "model",
    "Run": "simulation",
    "simulate": "simulation",
    "Stepper": "simulation",
    "State": "state",
    "set_threads": "threads",
}

__all__ = [
    "ModelBuilder",
    "Model",
    "State",
    "Contacts",
    "collide",
    "simulate",
    "Stepper",
    "Run",
    "InputError",
    "SimulationDiverged",
    "set_threads",
]
__version__ = "0.1.0"


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        value = getattr(import_module(f".{_LAZY[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'contactlab' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
