"""Finding a scene (a built-in name or a .toml path), reading it and turning it into a :class:`Scene`.

    scene = load_scene("bouncing_ball", overrides=["simulation.dt=0.0005"])
    run = scene.simulate()  # simulate(scene.model, scene.method, scene.dt, ..., scene_name=scene.name)

Order: read the text → parse TOML → apply ``--set`` overrides to the raw dict → validate
against the schema → build each ``[method.NAME]`` table into that method's Options (checked
there, once: ``simulate`` takes them as they are) → check that the selected method is
available → build the Model. Every mistake is an InputError.
"""

from __future__ import annotations

import codecs
import difflib
import functools
import os
import stat
from collections.abc import Sequence
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .. import methods
from ..errors import InputError
from ..model import Model
from .build import build_model
from .overrides import apply_overrides
from .schema import show, validate_scene
from .toml import parse_toml

if TYPE_CHECKING:
    from ..simulation import Checked, Run

BUILTIN_PACKAGE = __package__  # scene files live in <this package>/builtin/*.toml
MAX_SCENE_BYTES = 16 * 2**20  # bytes: a larger scene file is refused unread (built-in ones are under 2 kB)


@dataclass(frozen=True)
class Scene:
    """A loaded scene: the Model plus how to simulate it.

    name: built-in name or file stem; dt, duration [s]; method and integrator names;
    method_options: method name -> the raw ``[method.NAME]`` table (a dict), as written;
    description: one line; source: the file path, or ``builtin:NAME``; options: method name ->
    its ``Options`` (``contactlab.methods.NAME.Options``), built and checked once from its table,
    for every method with a table and the selected one (its defaults where it has none): what
    to pass to ``simulate``.
    """

    name: str
    model: Model
    method: str = "impulse"
    dt: float = 0.004
    duration: float = 2.0
    integrator: str = "symplectic_euler"
    method_options: dict[str, dict[str, Any]] = field(default_factory=dict)
    description: str = ""
    source: str = ""
    options: dict[str, Any] = field(default_factory=dict)

    def origin(self, overrides: Sequence[str] = ()) -> dict[str, Any]:
        """How to load this scene again from any folder, as a run's summary records it (its
        ``source``): ``{"scene": the built-in name or the file's absolute path, "overrides":
        the --set strings it was loaded with}``."""
        builtin = self.source.startswith("builtin:")
        return {
            "scene": self.source[len("builtin:") :] if builtin else os.path.abspath(self.source),
            "overrides": [str(line) for line in overrides],
        }

    def simulate(self, **keywords: Any) -> Run:
        """``simulate`` this scene as it says (its model, method, dt, duration, selected method's
        options and integrator, named after it); ``keywords`` are the rest of ``simulate``'s
        (progress, trajectory, record_every, threads, ...). What the CLI, a comparison and a
        sweep each run."""
        from ..simulation import simulate  # here: loading a scene does not load the stepping code

        return simulate(*self._run_arguments(), scene_name=self.name, **keywords)

    def check(self, **keywords: Any) -> Checked:
        """Every check :meth:`simulate` would make before its first step, with the same
        ``keywords`` (record_every, memory_limit, trajectory), plus ``streamed`` and ``remedies``
        (:func:`contactlab.simulation.check_run`): InputError for a run that would be refused."""
        from ..simulation import check_run

        return check_run(*self._run_arguments(), scene_name=self.name, **keywords)

    def _run_arguments(self) -> tuple[Model, str, float, float, Any, str]:
        """simulate's first six: model, method, dt, duration, the method's options, integrator."""
        return self.model, self.method, self.dt, self.duration, self.options[self.method], self.integrator


def _builtin_dir():
    return resources.files(BUILTIN_PACKAGE).joinpath("builtin")


@functools.cache
def _builtin_names():
    return tuple(
        sorted(entry.name[: -len(".toml")] for entry in _builtin_dir().iterdir() if entry.name.endswith(".toml"))
    )


def builtin_scenes() -> list[tuple[str, str]]:
    """(name, description) of every built-in scene, sorted by name."""
    result = []
    for name in _builtin_names():
        raw = parse_toml(_builtin_dir().joinpath(f"{name}.toml").read_text(encoding="utf-8"))
        result.append((name, raw.get("description", "")))
    return result


def _not_a_file(mode):
    """What a non-regular file is, in words (from its ``os.stat`` mode)."""
    kinds = (
        (stat.S_ISDIR, "the directory"),
        (stat.S_ISCHR, "the character device"),
        (stat.S_ISBLK, "the block device"),
        (stat.S_ISFIFO, "the FIFO (named pipe)"),
        (stat.S_ISSOCK, "the socket"),
    )
    return next((words for test, words in kinds if test(mode)), "the special file")


def _read_file(path):
    """The UTF-8 text of the scene file ``path``: a regular file of at most MAX_SCENE_BYTES,
    looked at with ``os.stat`` before it is opened (a FIFO or /dev/zero is never read)."""
    shown = repr(str(path))
    try:
        status = os.stat(path)
    except FileNotFoundError:
        raise InputError("", f"no such file {shown}") from None
    except (OSError, ValueError) as error:  # ValueError: a NUL character in the path
        raise InputError("", f"cannot read {shown} ({getattr(error, 'strerror', None) or error})") from None
    if not stat.S_ISREG(status.st_mode):
        raise InputError("", f"expected a .toml file, found {_not_a_file(status.st_mode)} {shown}")
    if status.st_size > MAX_SCENE_BYTES:
        raise InputError(
            "",
            f"the scene file {shown} is {status.st_size / 2**20:.1f} MiB, more than the "
            f"{MAX_SCENE_BYTES // 2**20} MiB a scene file may be",
        )
    try:
        with open(path, "rb") as stream:
            data = stream.read(MAX_SCENE_BYTES + 1)
    except OSError as error:
        raise InputError("", f"cannot read {shown} ({error.strerror or error})") from None
    if len(data) > MAX_SCENE_BYTES:  # it grew since the stat
        raise InputError(
            "", f"the scene file {shown} is more than the {MAX_SCENE_BYTES // 2**20} MiB a scene file may be"
        )
    start = len(codecs.BOM_UTF8) if data.startswith(codecs.BOM_UTF8) else 0  # the byte-order mark some editors
    try:  # (Notepad) write is no part of the text
        return data[start:].decode("utf-8")
    except UnicodeDecodeError as error:
        offset = start + error.start
        raise InputError(
            "", f"expected UTF-8 text, found a byte 0x{data[offset]:02x} at offset {offset} that is not"
        ) from None


def read_source(source: str | os.PathLike[str]) -> tuple[str, str, str]:
    """(name, text, origin) of a built-in name or a path to a .toml file."""
    text_source = os.fspath(source) if isinstance(source, os.PathLike) else source
    if not isinstance(text_source, str) or not text_source:
        raise InputError("", f"expected a built-in scene name or a path to a .toml file, found {show(source)}")
    looks_like_path = (
        isinstance(source, os.PathLike)
        or text_source.endswith(".toml")
        or os.sep in text_source
        or "/" in text_source
        or os.path.exists(text_source)
    )
    if looks_like_path:
        return Path(text_source).stem, _read_file(text_source), text_source
    names = _builtin_names()
    if text_source not in names:
        close = difflib.get_close_matches(text_source, names, n=3)
        hint = f" (did you mean {', '.join(show(c) for c in close)}?)" if close else ""
        raise InputError(
            "",
            f"unknown built-in scene {show(text_source)}{hint}; run `contactlab scenes` "
            f"to list them, or give the path of a .toml file",
        )
    text = _builtin_dir().joinpath(f"{text_source}.toml").read_text(encoding="utf-8")
    return text_source, text, f"builtin:{text_source}"


def _method_options(scene):
    """Method name -> its Options, built from the ``[method.NAME]`` table of every available
    method that has one, and for the selected method (from no table: its defaults); InputError
    naming the table's key, or "simulation.method" for an unavailable selected method."""
    built = {
        name: methods.make_options(methods.get(name), table, f"method.{name}")
        for name, table in scene["method"].items()
        if name in methods.AVAILABLE
    }
    selected = scene["simulation"]["method"]
    try:
        module = methods.get(selected)
    except InputError as error:
        raise InputError("simulation.method", error.message) from None
    if selected not in built:
        built[selected] = module.Options()
    return built


def load_scene(source: str | os.PathLike[str], overrides: str | Sequence[str] = ()) -> Scene:
    """Load a scene from a built-in name (``"bouncing_ball"``) or a path to a .toml file.

    overrides: ``"dotted.path=VALUE"`` strings (``--set``), applied before validation.
    Raises InputError, with the field path of the mistake, for anything wrong.
    """
    name, text, origin = read_source(source)
    return scene_from_raw(name, parse_toml(text), origin, overrides)


def scene_from_raw(name: str, raw: dict, origin: str, overrides: str | Sequence[str] = ()) -> Scene:
    """:func:`load_scene` of a scene file already read and parsed (``read_source`` and the TOML
    dict ``raw``, which the overrides change in place): how a study checks many settings of one
    scene without reading it again for each."""
    raw = apply_overrides(raw, overrides)
    scene = validate_scene(raw)
    options = _method_options(scene)
    simulation = scene["simulation"]
    base = _builtin_dir() if origin.startswith("builtin:") else Path(origin).parent
    return Scene(
        name=name,
        model=build_model(scene, base),
        method=simulation["method"],
        dt=simulation["dt"],
        duration=simulation["duration"],
        integrator=simulation["integrator"],
        method_options=scene["method"],
        description=scene["description"],
        source=origin,
        options=options,
    )
