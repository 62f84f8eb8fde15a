"""Issue 23, deliverable 4: a typed public API. mypy (configured in pyproject.toml's [tool.mypy])
passes on the public modules it lists, every public function of those modules is fully
annotated, and the package as a whole keeps at least the annotated share it has reached.

"Public": a function or method whose name does not start with "_" (plus the ``__init__`` of a
public class), in a module and a class whose names do not either. "Fully annotated": every
parameter but ``self``/``cls`` and the return (``__init__`` may leave its return out)."""

import ast
import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised on Python 3.10 only
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "src" / "contactlab"
# the share of the package's public functions fully annotated when this test was last raised: it
# may grow, never fall (every public function is annotated: a new one must be too)
LEAST_SHARE = 1.0


def _checked_paths():
    """The files mypy checks: pyproject's [tool.mypy] files, folders expanded."""
    files = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["mypy"]["files"]
    paths = []
    for name in files:
        path = ROOT / name
        paths += sorted(path.rglob("*.py")) if path.is_dir() else [path]
    return paths


def _public_functions(path):
    """(name, fully annotated) of each public function and method of the module ``path``."""
    found = []

    def visit(body, owner):
        for node in body:
            if isinstance(node, ast.ClassDef) and not node.name.startswith("_"):
                visit(node.body, node.name)
            elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                if node.name.startswith("_") and not (node.name == "__init__" and owner is not None):
                    continue
                arguments = node.args.posonlyargs + node.args.args + node.args.kwonlyargs
                if owner is not None and arguments and arguments[0].arg in ("self", "cls"):
                    arguments = arguments[1:]
                arguments += [a for a in (node.args.vararg, node.args.kwarg) if a is not None]
                annotated = all(a.annotation is not None for a in arguments) and (
                    node.returns is not None or node.name == "__init__"
                )
                found.append(
                    (f"{path.relative_to(PACKAGE)}:{node.lineno} {owner + '.' if owner else ''}{node.name}", annotated)
                )

    visit(ast.parse(path.read_text(encoding="utf-8")).body, None)
    return found


def _package_modules():
    """Every module of the package outside private modules and folders (``lcp/_checks.py``)."""
    return [
        path
        for path in sorted(PACKAGE.rglob("*.py"))
        if not any(part.startswith("_") and part != "__init__.py" for part in path.relative_to(PACKAGE).parts)
    ]


def test_mypy_passes_on_the_public_modules():
    if importlib.util.find_spec("mypy") is None:
        print("mypy is not installed (pip install '.[test]'): the type check is skipped")
        pytest.skip("mypy is not installed (pip install '.[test]')")
    result = subprocess.run([sys.executable, "-m", "mypy"], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stdout[-4000:] + result.stderr[-2000:]


def test_every_public_function_of_the_checked_modules_is_annotated():
    missing = [name for path in _checked_paths() for name, annotated in _public_functions(path) if not annotated]
    assert not missing, "not fully annotated: " + ", ".join(missing)


def test_the_package_keeps_its_annotated_share():
    functions = [entry for path in _package_modules() for entry in _public_functions(path)]
    share = sum(annotated for _, annotated in functions) / len(functions)
    assert share >= LEAST_SHARE, f"{share:.1%} of {len(functions)} public functions fully annotated"


def test_what_contactlab_exports_is_annotated():
    # ModelBuilder, Model, State, Contacts, Run (their public methods), simulate, set_threads, the errors, collide
    exported = ["builder.py", "model.py", "state.py", "contacts.py", "simulation.py", "threads.py", "errors.py"]
    missing = [name for file in exported for name, annotated in _public_functions(PACKAGE / file) if not annotated]
    missing += [
        name
        for name, annotated in _public_functions(PACKAGE / "collision" / "__init__.py")
        if name.endswith(" collide") and not annotated
    ]
    assert not missing, "not fully annotated: " + ", ".join(missing)
