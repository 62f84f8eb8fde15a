"""``--set PATH=VALUE`` overrides, applied to the raw TOML dict before validation.

PATH is dotted; integer parts index lists: ``bodies.0.velocity`` (``bodies[0].velocity`` is
accepted too, the form error messages use). VALUE is read as a TOML value
(``[3, 0, 0]``, ``0.001``, ``true``, ``"text"``); if it is not valid TOML it is taken as a
plain string, so ``simulation.method=penalty`` works. A missing key inside an existing table
is created (and then validated like any key, so a typo gets a "did you mean"); an index past
the end of a list is an error.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from ..errors import InputError
from .schema import path_join, show
from .toml import TOMLDecodeError, loads

FIELD = "--set"


def parse_value(text: str) -> Any:
    """A TOML value, or the text itself where it is not one (InputError for one nested too deep)."""
    try:
        return loads("value = " + text, FIELD)["value"]
    except TOMLDecodeError:
        return text


def parse_override(assignment: str) -> tuple[list[str | int], Any]:
    """``"a.0.b=VALUE"`` -> (["a", 0, "b"], value)."""
    if not isinstance(assignment, str) or "=" not in assignment:
        raise InputError(FIELD, f"expected PATH=VALUE (for example simulation.dt=0.001), found {show(assignment)}")
    path_text, value_text = (part.strip() for part in assignment.split("=", 1))
    if not path_text:
        raise InputError(
            FIELD, f"expected a path before '=' (for example simulation.dt=0.001), found {show(assignment)}"
        )
    parts = path_text.replace("[", ".").replace("]", "").split(".")
    if any(not part.strip() for part in parts):
        raise InputError(
            FIELD, f"expected a path of names and indices separated by dots, found an empty part in {show(path_text)}"
        )
    path = [int(part) if part.strip().isdigit() else part.strip() for part in parts]
    return path, parse_value(value_text)


def _step(node, part, where, assignment, create_next=None):
    """The child ``part`` of ``node`` (creating a missing table when ``create_next`` is given)."""
    if isinstance(node, dict):
        key = str(part)
        if key not in node and create_next is not None:
            if isinstance(create_next, int):
                raise InputError(path_join(where, key), f"there is no list {key} to index in --set {show(assignment)}")
            node[key] = {}
        return node, key
    if isinstance(node, list):
        if not isinstance(part, int):
            raise InputError(
                where,
                f"this is a list, so --set {show(assignment)} must index it with a number "
                f"such as 0, found {show(part)}",
            )
        if part >= len(node):
            entries = {0: "no entries", 1: "1 entry, index 0"}.get(
                len(node), f"{len(node)} entries, indices 0 to {len(node) - 1}"
            )
            raise InputError(
                path_join(where, part),
                f"index {part} is out of range in --set {show(assignment)} ({where} has {entries})",
            )
        return node, part
    raise InputError(
        where, f"this is a value ({show(node)}), not a table, so --set {show(assignment)} cannot set anything inside it"
    )


def apply_overrides(raw: dict[str, Any], overrides: str | Sequence[str]) -> dict[str, Any]:
    """Apply each ``PATH=VALUE`` string of ``overrides`` to ``raw`` in place; returns ``raw``."""
    if isinstance(overrides, str):
        overrides = [overrides]
    for assignment in overrides:
        path, value = parse_override(assignment)
        node, where = raw, ""
        for depth, part in enumerate(path):
            last = depth == len(path) - 1
            container, key = _step(node, part, where, assignment, None if last else path[depth + 1])
            if last:
                container[key] = value
            else:
                node, where = container[key], path_join(where, key)
    return raw
