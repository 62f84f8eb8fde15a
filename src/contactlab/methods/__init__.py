"""Contact-response methods, one module per method of the lecture, each a ``step``.

A method module provides:

* ``Options``: a dataclass of its settings (the ``[method.NAME]`` table of a scene file),
  every field with a default and a docstring line;
* ``step(model, state, dt, options, integrator) -> (State, StepInfo)``: one time step that
  follows the method's loop (L1, L2 or L3) in named stages;
* optionally ``divergence_advice(model, dt, options, integrator) -> str``: the likely fix, one
  clause, that ``contactlab.health`` gives when a run of this method goes wrong (penalty: the
  time step or stiffness an explicit step could follow).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import fields
from functools import cache
from types import ModuleType

from ..errors import InputError
from .base import CollisionOptions as CollisionOptions  # re-exported: what every method builds on
from .base import KeptManifoldOptions as KeptManifoldOptions
from .base import StepInfo as StepInfo

AVAILABLE = ("penalty", "projection", "impulse", "constraints")


def method_names(methods: str | Sequence[str] | None, option: str = "--methods") -> list[str]:
    """The methods named (a list or a comma-separated string; None: all four), each once, checked:
    InputError naming ``option`` for an unknown one or none at all (``""``)."""
    if methods is None:
        return list(AVAILABLE)
    names = [name.strip() for name in (methods.split(",") if isinstance(methods, str) else methods)]
    names = list(dict.fromkeys(name for name in names if name))
    for name in names:
        if name not in AVAILABLE:
            raise InputError(option, f"unknown method {name!r}; expected some of: {', '.join(AVAILABLE)}")
    if not names:
        raise InputError(option, f"expected at least one of: {', '.join(AVAILABLE)}")
    return names


def get(name: str) -> ModuleType:
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


def make_options(module: ModuleType, table: dict[str, object], path: str) -> CollisionOptions:
    """Build ``module.Options`` from a scene-file table (dict); unknown keys are InputErrors. An
    empty table gives the defaults, built once (frozen, so shared: a tiny run's 30 µs of checks)."""
    import difflib

    if not table:
        return _defaults(module)
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


@cache
def _defaults(module: ModuleType) -> CollisionOptions:
    """``module.Options()``, once per method."""
    return module.Options()
