"""Scene-file schema v1: which keys each table takes, their kind, unit and default.

The schema is a few declarative tables (``TOP``, ``SIMULATION``, ``MATERIAL``, ``BODY``,
``PARTICLES``, ``CLOTH``, ``OBSTACLE``, ``ARRAY``) of :class:`Key` entries. :func:`validate` walks a raw
TOML dict against them and returns a normalized copy in which every key is present (``None``
where the key was left out and the builder supplies the default).

Structure and types are checked here (unknown keys, strings where numbers belong, lists of
the wrong length, non-finite numbers, a non-positive time step). Physical values — positive
mass and sizes, restitution in [0, 1], a non-zero normal or quaternion, known material
names — are checked by :class:`contactlab.builder.ModelBuilder`, which the loader calls with
the same argument names and whose errors it prefixes with the scene path.

Every error is an :class:`~contactlab.errors.InputError` whose field is the full path of the
offending value (``bodies[0].mass``) and whose message is one sentence.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

from .. import methods
from ..dynamics.integrators import INTEGRATORS
from ..errors import InputError
from ..shape_arguments import BODY_SHAPE_ARGUMENTS, OBSTACLE_SHAPE_ARGUMENTS, check_shape_arguments

# Shapes the schema knows but the library cannot simulate yet: a clear "not supported yet".
PLANNED_BODY_SHAPES = ("mesh",)
PLANNED_OBSTACLE_SHAPES = ()
MAX_ARRAY_COPIES = 1_000_000


def show(value: object, limit: int = 60) -> str:
    """A value for a message (TOML spelling, strings quoted as repr), shortened to about ``limit`` characters."""
    if isinstance(value, bool):
        text = "true" if value else "false"
    elif isinstance(value, str):
        text = repr(value)  # quoted as the builder and contactlab.methods quote names
    elif isinstance(value, (int, float)):
        text = repr(value)
    elif isinstance(value, dict):
        text = "a table {" + ", ".join(f"{k} = {show(v, limit)}" for k, v in value.items()) + "}"
    elif isinstance(value, list):
        text = "[" + ", ".join(show(v, limit) for v in value) + "]"
    else:
        text = str(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def path_join(path: str, key: str | int) -> str:
    """``bodies[0]`` + ``mass`` -> ``bodies[0].mass``; integers become ``[i]``."""
    if isinstance(key, int):
        return f"{path}[{key}]"
    return f"{path}.{key}" if path else key


def _unit(unit):
    return f" ({unit})" if unit else ""


# -- kinds of value ---------------------------------------------------------------------------
class Kind(Protocol):
    """What a :class:`Key`'s kind does: ``check`` a value found at ``field`` (InputError naming it)
    and return it normalized; ``describe`` it in a few words for the docs."""

    def check(self, value: Any, field: str, unit: str = "") -> Any: ...

    def describe(self) -> str: ...


class Number:
    """A finite int or float (never a bool), returned as float; ``positive`` demands > 0."""

    def __init__(self, positive: bool = False) -> None:
        self.positive = positive

    def check(self, value: Any, field: str, unit: str = "") -> Any:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise InputError(field, f"expected a number{_unit(unit)}, found {show(value)}")
        if not math.isfinite(value):
            raise InputError(field, f"expected a finite number{_unit(unit)}, found {show(value)}")
        if self.positive and value <= 0:
            raise InputError(field, f"expected a number greater than 0{_unit(unit)}, found {show(value)}")
        return float(value)

    def describe(self) -> str:
        return "number > 0" if self.positive else "number"


class Text:
    """A string on one line."""

    def check(self, value: Any, field: str, unit: str = "") -> Any:
        if not isinstance(value, str):
            raise InputError(field, f"expected a string, found {show(value)}")
        if "\n" in value or "\r" in value:
            raise InputError(field, f"expected a single line, found {show(value)}")
        return value

    def describe(self) -> str:
        return "string"


class Switch:
    """true or false (a TOML boolean, not a number or a string)."""

    def check(self, value: Any, field: str, unit: str = "") -> Any:
        if not isinstance(value, bool):
            raise InputError(field, f"expected true or false, found {show(value)}")
        return value

    def describe(self) -> str:
        return "true | false"


class Choice:
    """One of ``values``; names in ``planned`` get a "not supported yet" error."""

    def __init__(self, values: Collection[str], planned: Collection[str] = (), what: str = "value") -> None:
        self.values, self.planned, self.what = tuple(values), tuple(planned), what

    def check(self, value: Any, field: str, unit: str = "") -> Any:
        if not isinstance(value, str):
            raise InputError(field, f"expected one of {', '.join(self.values)}, found {show(value)}")
        if value in self.planned:
            raise InputError(
                field, f"the {self.what} {show(value)} is not supported yet; use one of {', '.join(self.values)}"
            )
        if value not in self.values:
            raise InputError(field, f"unknown {self.what} {show(value)}{did_you_mean(value, self.values)}")
        return value

    def describe(self) -> str:
        return " | ".join(self.values)


class Vector:
    """A list of ``size`` numbers; ``whole`` demands integers ≥ 1."""

    def __init__(self, size: int, whole: bool = False) -> None:
        self.size, self.whole = size, whole

    def check(self, value: Any, field: str, unit: str = "") -> Any:
        what = (
            f"a list of {self.size} whole numbers ≥ 1" if self.whole else f"a list of {self.size} numbers{_unit(unit)}"
        )
        if (
            not isinstance(value, list)
            or len(value) != self.size
            or any(isinstance(x, bool) or not isinstance(x, (int, float)) for x in value)
        ):
            raise InputError(field, f"expected {what}, found {show(value)}")
        if self.whole:
            if any(not isinstance(x, int) or x < 1 for x in value):
                raise InputError(field, f"expected {what}, found {show(value)}")
            return [int(x) for x in value]
        if not all(math.isfinite(x) for x in value):
            raise InputError(field, f"expected finite numbers{_unit(unit)}, found {show(value)}")
        return [float(x) for x in value]

    def describe(self) -> str:
        return f"[{', '.join('n' if self.whole else 'x' for _ in range(self.size))}]"


class _ListOf:
    """A non-empty list of values of the kind ``item``, each checked by it (``field[i]``)."""

    item: Any
    noun = ""
    """what a message calls the list, followed by its unit"""
    noun_says_unit = False

    def check(self, value: Any, field: str, unit: str = "") -> Any:
        if not isinstance(value, list) or not value:
            shown = "" if self.noun_says_unit else _unit(unit)
            raise InputError(field, f"expected a non-empty list of {self.noun}{shown}, found {show(value)}")
        return [self.item.check(x, f"{field}[{i}]", unit) for i, x in enumerate(value)]


class Points(_ListOf):
    """A non-empty list of [x, y, z] points."""

    item = Vector(3)
    noun = "[x, y, z] points"

    def describe(self) -> str:
        return "[[x, y, z], ...]"


class Times(_ListOf):
    """Keyframe times: a non-empty list of finite numbers, strictly increasing."""

    item = Number()
    noun = "times"

    def check(self, value: Any, field: str, unit: str = "") -> Any:
        times = super().check(value, field, unit)
        for i in range(1, len(times)):
            if times[i] <= times[i - 1]:
                raise InputError(
                    f"{field}[{i}]",
                    f"times must increase strictly, found {show(value[i])} after {show(value[i - 1])}{_unit(unit)}",
                )
        return times

    def describe(self) -> str:
        return "[t0, t1, ...]"


class Quaternions(_ListOf):
    """A non-empty list of [w, x, y, z] quaternions."""

    item = Vector(4)
    noun = "[w, x, y, z] quaternions"
    noun_says_unit = True
    """the unit, "quaternion w, x, y, z", would only say it again"""

    def describe(self) -> str:
        return "[[w, x, y, z], ...]"


class VectorOrKeyframes:
    """A force or torque: [x, y, z] (constant) or a list of them, one per keyframe time."""

    vector, points = Vector(3), Points()

    def check(self, value: Any, field: str, unit: str = "") -> Any:
        if isinstance(value, list) and value and all(isinstance(item, list) for item in value):
            return self.points.check(value, field, unit)
        return self.vector.check(value, field, unit)

    def describe(self) -> str:
        return "[x, y, z] or [[x, y, z], ...]"


class Inertia:
    """A body's inertia: three principal moments [Ixx, Iyy, Izz] or a 3×3 tensor (three rows of
    three); the builder checks the values (symmetry, positive definite, triangle inequality)."""

    vector = Vector(3)

    def check(self, value: Any, field: str, unit: str = "") -> Any:
        if isinstance(value, list) and len(value) == 3 and all(isinstance(row, list) for row in value):
            return [self.vector.check(row, f"{field}[{i}]", unit) for i, row in enumerate(value)]
        if isinstance(value, list) and any(isinstance(row, list) for row in value):
            what = f"[Ixx, Iyy, Izz] or three rows of three numbers{_unit(unit)}"
            raise InputError(field, f"expected {what}, found {show(value)}")
        return self.vector.check(value, field, unit)

    def describe(self) -> str:
        return "[Ixx, Iyy, Izz] or [[Ixx, Ixy, Ixz], [Ixy, Iyy, Iyz], [Ixz, Iyz, Izz]]"


class Pinned:
    """Cloth vertices: a list of whole numbers ≥ 0 (vertex indices) and names, or one of them."""

    def check(self, value: Any, field: str, unit: str = "") -> Any:
        items = value if isinstance(value, list) else [value]
        for i, item in enumerate(items):
            ok = isinstance(item, str) or (isinstance(item, int) and not isinstance(item, bool) and item >= 0)
            if not ok:
                where = f"{field}[{i}]" if isinstance(value, list) else field
                raise InputError(
                    where,
                    f"expected a vertex index (a whole number ≥ 0) or a vertex set name "
                    f'such as "corners", found {show(item)}',
                )
        return list(items)

    def describe(self) -> str:
        return "[index or name, ...]"


class Table:
    """A table with the keys of ``keys`` (a dict name -> Key); ``shapes``: for a table whose
    ``shape`` key picks a shape, the builder's table of which shape takes which key
    (contactlab.shape_arguments.BODY_SHAPE_ARGUMENTS or OBSTACLE_SHAPE_ARGUMENTS)."""

    def __init__(self, keys: Mapping[str, Key], shapes: Mapping[str, Sequence[str]] | None = None) -> None:
        self.keys, self.shapes = keys, shapes

    def check(self, value: Any, field: str, unit: str = "") -> Any:
        if not isinstance(value, dict):
            raise InputError(field, f"expected a table, found {show(value)}")
        return validate_table(value, self.keys, field, self.shapes)

    def describe(self) -> str:
        return "table"


class GridArray(Table):
    """The ``array`` table of a body or particle group: copies on a grid (see .build)."""

    def check(self, value: Any, field: str, unit: str = "") -> Any:
        array = super().check(value, field, unit)
        copies = math.prod(array["count"])
        if copies > MAX_ARRAY_COPIES:
            raise InputError(
                f"{field}.count",
                f"expected at most {MAX_ARRAY_COPIES} copies in all, found {show(array['count'])} = {copies}",
            )
        for axis, (count, spacing) in enumerate(zip(array["count"], array["spacing"])):
            if count > 1 and spacing == 0:
                raise InputError(
                    f"{field}.spacing",
                    f"expected a non-zero spacing along {'xyz'[axis]}, "
                    f"where count is {count}, found {show(array['spacing'])}",
                )
        return array


class TableList:
    """An array of tables (``[[name]]`` in TOML), each checked as ``Table``."""

    def __init__(self, keys: Mapping[str, Key], shapes: Mapping[str, Sequence[str]] | None = None) -> None:
        self.table = Table(keys, shapes)

    def check(self, value: Any, field: str, unit: str = "") -> Any:
        if not isinstance(value, list) or not all(isinstance(item, dict) for item in value):
            short = field.rsplit(".", 1)[-1]
            raise InputError(field, f"expected an array of tables written [[{short}]], found {show(value)}")
        return [self.table.check(item, f"{field}[{i}]") for i, item in enumerate(value)]

    def describe(self) -> str:
        return "array of tables"


class MethodTables:
    """``[method.NAME]`` tables: NAME a method of contactlab.methods, the content kept as is
    (its keys are validated against the method's Options by the loader)."""

    names = methods.AVAILABLE

    def check(self, value: Any, field: str, unit: str = "") -> Any:
        if not isinstance(value, dict):
            raise InputError(field, f"expected tables [method.NAME], found {show(value)}")
        for name, table in value.items():
            if name not in self.names:
                raise InputError(path_join(field, name), f"unknown method {show(name)}{did_you_mean(name, self.names)}")
            if not isinstance(table, dict):
                raise InputError(path_join(field, name), f"expected a table of options, found {show(table)}")
        return {name: dict(table) for name, table in value.items()}

    def describe(self) -> str:
        return "tables"


@dataclass(frozen=True)
class Key:
    """One key of a table: its kind, unit, default and, for shape-specific keys, the shapes."""

    kind: Kind
    default: object = None
    """None: left to the builder (or absent)"""
    unit: str = ""
    required: bool = False
    shapes: tuple[str, ...] = ()
    """non-empty: only these shapes take the key"""


def taking(name: str, table: Mapping[str, Sequence[str]]) -> tuple[str, ...]:
    """The shapes of ``table`` (contactlab.shape_arguments' BODY_ or OBSTACLE_SHAPE_ARGUMENTS) that
    take the argument ``name``: the builder says which shape takes which key, once."""
    return tuple(shape for shape, names in table.items() if name in names)


def did_you_mean(word: object, known: Collection[str]) -> str:
    """The end of a message naming an unknown ``word``: the closest of ``known``, else all of them."""
    close = difflib.get_close_matches(str(word), list(known), n=1)
    if close:
        return f"; did you mean {show(close[0])}?"
    return f"; expected one of: {', '.join(known)}"


# -- the schema -------------------------------------------------------------------------------
SIMULATION = {
    "dt": Key(Number(positive=True), 0.004, "s"),
    "duration": Key(Number(positive=True), 2.0, "s"),
    "gravity": Key(Vector(3), [0.0, 0.0, -9.81], "m/s^2"),
    "method": Key(Choice(methods.AVAILABLE, what="method"), "impulse"),
    "integrator": Key(Choice(INTEGRATORS, what="integrator"), "symplectic_euler"),
}

MATERIAL = {
    "name": Key(Text(), required=True),
    "friction": Key(Number(), 0.5, "Coulomb mu"),
    "restitution": Key(Number(), 0.0, "epsilon"),
}

ARRAY = {"count": Key(Vector(3, whole=True), required=True), "spacing": Key(Vector(3), required=True, unit="m")}

PATH = {
    "times": Key(Times(), required=True, unit="s"),
    "positions": Key(Points(), required=True, unit="m"),
    "orientations": Key(Quaternions(), unit="quaternion w, x, y, z"),
}

BODY = {
    "name": Key(Text()),
    "shape": Key(Choice(("sphere", "box", "capsule", "convex"), PLANNED_BODY_SHAPES, what="body shape"), required=True),
    "radius": Key(Number(), unit="m", shapes=taking("radius", BODY_SHAPE_ARGUMENTS)),
    "half_extents": Key(Vector(3), unit="m", shapes=taking("half_extents", BODY_SHAPE_ARGUMENTS)),
    "half_length": Key(Number(), unit="m", shapes=taking("half_length", BODY_SHAPE_ARGUMENTS)),
    "points": Key(Points(), unit="m", shapes=taking("points", BODY_SHAPE_ARGUMENTS)),
    "file": Key(Text(), shapes=taking("file", BODY_SHAPE_ARGUMENTS)),
    "scale": Key(Number(positive=True), 1.0, shapes=taking("scale", BODY_SHAPE_ARGUMENTS)),
    "mass": Key(Number(), unit="kg"),
    "density": Key(Number(), unit="kg/m^3"),
    "inertia": Key(Inertia(), unit="kg m^2"),
    "position": Key(Vector(3), [0.0, 0.0, 0.0], "m"),
    "orientation": Key(Vector(4), [1.0, 0.0, 0.0, 0.0], "quaternion w, x, y, z"),
    "velocity": Key(Vector(3), [0.0, 0.0, 0.0], "m/s"),
    "angular_velocity": Key(Vector(3), [0.0, 0.0, 0.0], "rad/s"),
    "material": Key(Text()),
    "array": Key(GridArray(ARRAY)),
    "path": Key(Table(PATH)),
}

FORCE = {
    "body": Key(Text(), required=True),
    "force": Key(VectorOrKeyframes(), unit="N"),
    "torque": Key(VectorOrKeyframes(), unit="N m"),
    "times": Key(Times(), unit="s"),
}

PARTICLES = {
    "position": Key(Points(), required=True, unit="m"),
    "velocity": Key(Points(), unit="m/s"),
    "mass": Key(Number(), 1.0, "kg"),
    "radius": Key(Number(), 0.0, "m"),
    "material": Key(Text()),
    "array": Key(GridArray(ARRAY)),
}

CLOTH = {
    "name": Key(Text()),
    "size": Key(Vector(2), unit="m"),
    "resolution": Key(Vector(2, whole=True)),
    "file": Key(Text()),
    "scale": Key(Number(positive=True), 1.0),
    "position": Key(Vector(3), [0.0, 0.0, 0.0], "m"),
    "orientation": Key(Vector(4), [1.0, 0.0, 0.0, 0.0], "quaternion w, x, y, z"),
    "velocity": Key(Vector(3), [0.0, 0.0, 0.0], "m/s"),
    "mass": Key(Number(), unit="kg"),
    "density": Key(Number(), unit="kg/m^2"),
    "stretch_stiffness": Key(Number(), 1000.0, "N/m"),
    "shear_stiffness": Key(Number(), 100.0, "N/m"),
    "bend_stiffness": Key(Number(), 10.0, "N/m"),
    "damping": Key(Number(), 0.0, "N s/m"),
    "pinned": Key(Pinned(), []),
    "thickness": Key(Number(), 0.005, "m"),
    "self_collision": Key(Switch(), True),
    "material": Key(Text()),
}

OBSTACLE = {
    "shape": Key(
        Choice(("plane", "sphere", "box", "convex", "mesh"), PLANNED_OBSTACLE_SHAPES, what="obstacle shape"),
        required=True,
    ),
    "normal": Key(Vector(3), shapes=taking("normal", OBSTACLE_SHAPE_ARGUMENTS)),
    "offset": Key(Number(), 0.0, "m", shapes=taking("offset", OBSTACLE_SHAPE_ARGUMENTS)),
    "radius": Key(Number(), unit="m", shapes=taking("radius", OBSTACLE_SHAPE_ARGUMENTS)),
    "half_extents": Key(Vector(3), unit="m", shapes=taking("half_extents", OBSTACLE_SHAPE_ARGUMENTS)),
    "points": Key(Points(), unit="m", shapes=taking("points", OBSTACLE_SHAPE_ARGUMENTS)),
    "file": Key(Text(), shapes=taking("file", OBSTACLE_SHAPE_ARGUMENTS)),
    "scale": Key(Number(positive=True), 1.0, shapes=taking("scale", OBSTACLE_SHAPE_ARGUMENTS)),
    "position": Key(Vector(3), [0.0, 0.0, 0.0], "m", shapes=taking("position", OBSTACLE_SHAPE_ARGUMENTS)),
    "orientation": Key(
        Vector(4), [1.0, 0.0, 0.0, 0.0], "quaternion w, x, y, z", shapes=taking("orientation", OBSTACLE_SHAPE_ARGUMENTS)
    ),
    "material": Key(Text()),
}

TOP = {
    "description": Key(Text(), ""),
    "simulation": Key(Table(SIMULATION), {}),
    "method": Key(MethodTables(), {}),
    "materials": Key(TableList(MATERIAL), []),
    "bodies": Key(TableList(BODY, BODY_SHAPE_ARGUMENTS), []),
    "particles": Key(TableList(PARTICLES), []),
    "cloth": Key(TableList(CLOTH), []),
    "obstacles": Key(TableList(OBSTACLE, OBSTACLE_SHAPE_ARGUMENTS), []),
    "forces": Key(TableList(FORCE), []),
}

TABLES = {
    "top level": TOP,
    "[simulation]": SIMULATION,
    "[[materials]]": MATERIAL,
    "[[bodies]]": BODY,
    "[[particles]]": PARTICLES,
    "[[cloth]]": CLOTH,
    "[[obstacles]]": OBSTACLE,
    "array": ARRAY,
    "path": PATH,
    "[[forces]]": FORCE,
}


def validate_table(
    table: Mapping[str, Any],
    keys: Mapping[str, Key],
    path: str,
    shapes: Mapping[str, Sequence[str]] | None = None,
) -> dict[str, Any]:
    """Check ``table`` against ``keys``; a normalized dict with every key (None where absent).
    ``shapes`` (see Table): the table's ``shape`` key picks which shape-specific keys it takes."""
    shape_key = "shape" if shapes is not None else None
    for name in table:
        if name not in keys:
            raise InputError(path_join(path, name), f"unknown key{did_you_mean(name, keys)}")
    for name, key in keys.items():
        if key.required and name not in table:
            hint = f" (one of {', '.join(key.kind.values)})" if isinstance(key.kind, Choice) else ""
            raise InputError(path_join(path, name), f"missing required key {show(name)}{hint}")
    result = {}
    shape = None
    if shape_key is not None:
        shape = result[shape_key] = keys[shape_key].kind.check(table[shape_key], path_join(path, shape_key))
    for name, key in keys.items():
        if name == shape_key:
            continue
        if name not in table:
            default = key.default if not key.shapes or shape in key.shapes else None
            if isinstance(key.kind, Table) and default is not None:
                default = key.kind.check(default, path_join(path, name))
            result[name] = list(default) if isinstance(default, list) else default
            continue
        if key.shapes and shape not in key.shapes:
            try:
                check_shape_arguments(shape, shapes, [name])  # type: ignore[arg-type]  # a shape key: shapes given
            except InputError as error:
                raise InputError(path_join(path, name), error.message) from None
        result[name] = key.kind.check(table[name], path_join(path, name), key.unit)
    return result


def validate_scene(raw: object) -> dict[str, Any]:
    """The whole scene: a normalized dict with the keys of ``TOP``; InputError on the first mistake."""
    if not isinstance(raw, dict):
        raise InputError("", f"expected a TOML document (a table), found {show(raw)}")
    return validate_table(raw, TOP, "")
