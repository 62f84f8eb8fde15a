"""Issue 36: layers that hold — the import contract of src/contactlab.

The layers are the ``## Layer N: …`` sections of docs/modules.md. Each module is named in the
first column of one of their tables — by its path (``methods/penalty.py``), by its file name or a
pattern after its folder's path in the same cell (``collision/narrow_phase.py``, ``families.py``,
``capsule*.py``), or by its folder (``lcp/``) — so the map a reader sees is the one the suite
holds. Read with ``ast``, never imported, every import of a contactlab module is checked:

* **Downward only:** an import, at module level or inside a function, goes to a module of the
  same layer or a lower one. ``from contactlab import name`` (``from . import name``) imports the
  module ``contactlab.name`` where there is one, else the package itself (its ``__init__.py``,
  the public face, layer 6: inside the package a name is imported from the module that defines
  it). Importing ``contactlab.a.b`` also runs the package ``contactlab.a``: that counts as an
  import of it too, unless the importer is inside it (then it is already running).
* **Imports under ``if TYPE_CHECKING:`` do not count,** for the layers or for cycles: they never
  run. Every module that has them starts with ``from __future__ import annotations`` (checked
  here), so the names they bring appear in annotations only, which Python never evaluates: they
  cost no import and close no cycle at run time, and they let a lower layer's annotation name
  the higher layer's object it is handed (``SimulationDiverged.run`` is a ``Run``).
* **No cycles** among the modules, the imports inside functions counted.
* **The compiled core (layers 1–3) imports no h5py, Matplotlib, Dask or distributed:** not
  itself, not through any contactlab module it imports (inside functions included), and a fresh
  interpreter that imports every module of those layers has none of them loaded.
"""

import ast
import fnmatch
import os
import re
import subprocess
import sys
from functools import cache
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "src" / "contactlab"
MODULE_MAP = ROOT / "docs" / "modules.md"
CORE = 3  # layers 1-3: data, detection and free motion, responses and solvers
HEAVY = ("h5py", "matplotlib", "dask", "distributed")  # what the compiled core never imports


def _module_name(path):
    """contactlab.a.b of the file a/b.py (a/__init__.py: contactlab.a), relative to PACKAGE."""
    parts = ["contactlab", *Path(path).with_suffix("").parts]
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


@cache
def _files():
    """module name -> its path relative to PACKAGE (posix), every .py file of the package."""
    paths = sorted(path.relative_to(PACKAGE).as_posix() for path in PACKAGE.rglob("*.py"))
    return {_module_name(path): path for path in paths}


def _layer_sections():
    """[(layer number, [the names of each row's first cell, as read])] from docs/modules.md."""
    text = MODULE_MAP.read_text(encoding="utf-8")
    sections = re.split(r"^## ", text, flags=re.M)
    layers = []
    for section in sections:
        heading = re.match(r"Layer (\d+)\b", section)
        if heading is None:
            continue
        cells = [line.split("|")[1] for line in section.splitlines() if line.startswith("| `")]
        layers.append((int(heading.group(1)), [re.findall(r"`([\w*./]+)`", cell) for cell in cells]))
    return layers


@cache
def _layers():
    """path -> [every layer whose section names it]; and the names that name no module."""
    named: dict[str, list[int]] = {}
    unknown = []
    for layer, cells in _layer_sections():
        for names in cells:
            folder = ""
            for name in names:
                if name.endswith("/"):  # a folder: every module under it
                    covered = [path for path in _files().values() if path.startswith(name)]
                else:
                    if "/" in name:
                        folder = name.rsplit("/", 1)[0] + "/"
                        pattern = name
                    else:  # a file name or pattern, in the folder of the cell's last path
                        pattern = folder + name
                    covered = [path for path in _files().values() if fnmatch.fnmatchcase(path, pattern)]
                if not covered:
                    unknown.append(f"docs/modules.md names `{name}` in layer {layer}: no module of src/contactlab is")
                for path in covered:
                    named.setdefault(path, []).append(layer)
    return named, unknown


def _layer(module):
    """The module's layer; 0 for one the map leaves out (test_every_module_has_one_layer says so)."""
    return _layers()[0].get(_files()[module], [0])[0]


def _type_checking(test):
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def _imports_of(module):
    """[(target, line, under TYPE_CHECKING)] of every import in ``module``'s file, at any depth:
    targets are contactlab module names or the top-level names of other packages."""
    path = _files()[module]
    package = module if path.endswith("__init__.py") else module.rsplit(".", 1)[0]
    found = []

    def targets(name, imported, line, typing_only):
        if name.split(".")[0] != "contactlab":
            found.append((name.split(".")[0], line, typing_only))
            return
        modules = {f"{name}.{each}" if f"{name}.{each}" in _files() else name for each in imported or [None]}
        for target in modules:
            assert target in _files(), f"{path}:{line} imports {target}, which is no module of contactlab"
            found.append((target, line, typing_only))
            # importing contactlab.a.b runs the packages above it too, but those holding the importer
            parts = target.split(".")
            for end in range(2, len(parts)):
                above = ".".join(parts[:end])
                if not module.startswith(above + "."):
                    found.append((above, line, typing_only))

    def visit(node, typing_only):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.If) and _type_checking(child.test):
                for statement in child.body:
                    visit_one(statement, True)
                for statement in child.orelse:
                    visit_one(statement, typing_only)
            else:
                visit_one(child, typing_only)

    def visit_one(node, typing_only):
        if isinstance(node, ast.Import):
            for alias in node.names:
                targets(alias.name, None, node.lineno, typing_only)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                name = ".".join(base + ([node.module] if node.module else []))
            else:
                name = node.module
            targets(name, [alias.name for alias in node.names], node.lineno, typing_only)
        visit(node, typing_only)

    visit(ast.parse((PACKAGE / path).read_text(encoding="utf-8")), False)
    return found


@cache
def _graph():
    """module -> {contactlab module or other top-level package: first line importing it}, the
    imports that run (module level and inside functions), not those under TYPE_CHECKING."""
    graph = {}
    for module in _files():
        edges: dict[str, int] = {}
        for target, line, typing_only in _imports_of(module):
            if not typing_only and target != module:
                edges.setdefault(target, line)
        graph[module] = edges
    return graph


def test_every_module_has_one_layer():
    layers, unknown = _layers()
    missing = [
        f"src/contactlab/{path} has no layer: name it in one '## Layer N' section of docs/modules.md"
        for path in _files().values()
        if path not in layers
    ]
    twice = [
        f"src/contactlab/{path} is named in layers {named}" for path, named in layers.items() if len(set(named)) > 1
    ]
    assert sorted(number for number, _ in _layer_sections()) == [1, 2, 3, 4, 5, 6]
    assert len(_files()) > 100
    problems = missing + twice + unknown
    assert not problems, "\n".join(problems)


def test_every_import_goes_to_the_same_or_a_lower_layer():
    upward = [
        f"src/contactlab/{_files()[module]}:{line} (layer {_layer(module)}) imports {target} (layer {_layer(target)})"
        for module, edges in _graph().items()
        for target, line in edges.items()
        if target in _files() and _layer(target) > _layer(module) > 0
    ]
    assert not upward, "\n".join(upward)


def test_imports_under_type_checking_are_annotations_only():
    # they never run only if the annotations naming them are never evaluated
    lazy = []
    for module, path in _files().items():
        if any(typing_only for _, _, typing_only in _imports_of(module)):
            tree = ast.parse((PACKAGE / path).read_text(encoding="utf-8"))
            futures = [node for node in tree.body if isinstance(node, ast.ImportFrom) and node.module == "__future__"]
            if not any(alias.name == "annotations" for node in futures for alias in node.names):
                lazy.append(path)
    assert not lazy, "\n".join(
        f"src/contactlab/{path}: imports under TYPE_CHECKING without `from __future__ import annotations`"
        for path in lazy
    )


def _cycles(graph):
    """The strongly connected components of more than one module (Tarjan's algorithm)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    components = []

    def connect(module):
        index[module] = low[module] = len(index)
        stack.append(module)
        for target in graph[module]:
            if target not in graph:
                continue
            if target not in index:
                connect(target)
                low[module] = min(low[module], low[target])
            elif target in stack:
                low[module] = min(low[module], index[target])
        if low[module] == index[module]:
            component = []
            while True:
                member = stack.pop()
                component.append(member)
                if member == module:
                    break
            if len(component) > 1:
                components.append(sorted(component))

    for module in sorted(graph):
        if module not in index:
            connect(module)
    return components


def test_no_import_cycles_counting_imports_inside_functions():
    cycles = _cycles(_graph())
    assert not cycles, "\n".join("import cycle: " + " <-> ".join(cycle) for cycle in cycles)


def test_the_cycle_finder_finds_a_cycle_through_a_function_level_import():
    graph = {"a": {"b": 1}, "b": {"c": 3}, "c": {"a": 9, "numpy": 2}, "d": {"a": 1}}
    assert _cycles(graph) == [["a", "b", "c"]]


def _core():
    return [module for module in _files() if 0 < _layer(module) <= CORE]


def test_the_compiled_core_reaches_no_hdf5_plotting_or_dask():
    graph = _graph()
    reached = {}
    for start in _core():  # every module a core module can import, through any chain of imports
        seen, todo = {start}, [start]
        while todo:
            for target in graph.get(todo.pop(), {}):
                if target not in seen:
                    seen.add(target)
                    todo.append(target)
        heavy = sorted(seen & set(HEAVY))
        if heavy:
            reached[_files()[start]] = heavy
    assert not reached, "\n".join(
        f"src/contactlab/{path} reaches {', '.join(heavy)}" for path, heavy in reached.items()
    )


def test_importing_the_compiled_core_loads_no_hdf5_plotting_or_dask():
    program = (
        "import importlib, sys\n"
        f"for name in {_core()!r}:\n"
        "    importlib.import_module(name)\n"
        f"print(sorted(name for name in {HEAVY!r} if name in sys.modules))\n"
    )
    path = os.pathsep.join([str(PACKAGE.parent), os.environ.get("PYTHONPATH", "")])
    result = subprocess.run(
        [sys.executable, "-c", program],
        capture_output=True,
        text=True,
        env={**os.environ, "PYTHONPATH": path},
        timeout=300,
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "[]"
