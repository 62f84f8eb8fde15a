"""Contact-response methods, one module per method of the lecture, each a ``step``.

A method module provides:

* ``Options``: a dataclass of its settings (the ``[method.NAME]`` table of a scene file),
  every field with a default and a docstring line;
* ``step(model, state, dt, options, integrator) -> (State, StepInfo)``: one time step that
  follows the method's loop (L1, L2 or L3) in named stages;
* optionally ``prepare(model, dt, options, integrator) -> Options``: called once before the
  first step to resolve settings that depend on the scene (e.g. an "auto" stiffness) and to
  warn about ones that cannot work (``StabilityWarning``).
"""

from dataclasses import dataclass, fields

from ..contacts import Contacts
from ..errors import InputError


@dataclass
class StepInfo:
    """What a step reports besides the new state."""
    contacts: Contacts            # the contacts the response acted on
    solver_iterations: int = 0    # sweeps the solver made (0 where there is none)
    solver_residual: float = 0.0  # the solver's last change or residual (method-specific units, documented)
    energy_elastic: float = 0.0   # energy stored in contact springs [J]


AVAILABLE = ("penalty", "projection", "impulse", "constraints")


def check_choices(options, allowed):
    """InputError unless each option named in ``allowed`` (name -> tuple of values) is one of them."""
    for name, values in allowed.items():
        if getattr(options, name) not in values:
            raise InputError(name, f"expected one of {', '.join(values)}, found {getattr(options, name)!r}")


def check_counts(options, least):
    """InputError unless each option named in ``least`` (name -> minimum) is a whole number ≥ it."""
    for name, minimum in least.items():
        value = getattr(options, name)
        if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
            raise InputError(name, f"expected a whole number ≥ {minimum}, found {value!r}")


def get(name):
    """The method module called ``name``; InputError for an unknown or unavailable one."""
    if name == "impulse":
        from . import impulse
        return impulse
    if name == "penalty":
        from . import penalty
        return penalty
    if name == "projection":
        from . import projection
        return projection
    if name == "constraints":
        from . import constraints
        return constraints
    raise InputError("method", f"unknown method {name!r}; expected one of: {', '.join(AVAILABLE)}")


def make_options(module, table, path):
    """Build ``module.Options`` from a scene-file table (dict); unknown keys are InputErrors."""
    import difflib
    known = {f.name: f for f in fields(module.Options)}
    values = {}
    for key, value in table.items():
        if key not in known:
            close = difflib.get_close_matches(key, known, n=1)
            hint = f"; did you mean {close[0]!r}?" if close else f"; known keys: {', '.join(known)}"
            raise InputError(f"{path}.{key}", f"unknown option{hint}")
        values[key] = value
    try:
        return module.Options(**values)
    except InputError as error:
        raise InputError(f"{path}.{error.field}", error.message) from None
