"""Issue 23: the habits of a maintained library, held by the suite — ruff's lint and format clean
over src/ and tests/ (the settings in pyproject.toml) and no module over 1,000 lines. That the
module map (docs/modules.md) names every module, in one layer, is tests/test_layers.py's."""

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "src" / "contactlab"
# lines: a module longer than this holds more than one concern (issue 23's 600, made "one concern a
# file, at most about 1,000 lines" by issue 36: a split at a line count cut concerns in two)
LONGEST_MODULE = 1000


def _ruff(*arguments):
    """ruff as this interpreter's module (the test extra installs it beside pytest), so it runs
    whether or not the environment's bin folder is on PATH; skipped where it is not installed."""
    if importlib.util.find_spec("ruff") is None:
        print("ruff is not installed (pip install '.[test]' brings it): the lint check is skipped")
        pytest.skip("ruff is not installed (pip install '.[test]' brings it)")
    command = [sys.executable, "-m", "ruff", *arguments, "src", "tests"]
    return subprocess.run(command, cwd=ROOT, capture_output=True, text=True)


def test_ruff_finds_nothing_to_lint():
    result = _ruff("check", "--no-cache")
    assert result.returncode == 0, result.stdout + result.stderr


def test_ruff_finds_nothing_to_format():
    result = _ruff("format", "--check", "--no-cache")
    assert result.returncode == 0, result.stdout + result.stderr


def _modules():
    """Every module of the package but empty package markers, as paths relative to it."""
    paths = (path for path in PACKAGE.rglob("*.py") if path.stat().st_size > 0)
    return sorted(path.relative_to(PACKAGE).as_posix() for path in paths)


def test_no_module_is_longer_than_a_thousand_lines():
    lengths = {name: len((PACKAGE / name).read_text(encoding="utf-8").splitlines()) for name in _modules()}
    assert len(lengths) > 100
    assert {name: n for name, n in lengths.items() if n > LONGEST_MODULE} == {}


# parameters: a function of the methods that takes more reads as a bag of arrays, not as its stage
# of the loop (issue 36, item 5); what belongs together travels as one named value (a LoopModel, a
# Motion, a Specialization, (u, targets, warm start, order) of a solve)
MOST_PARAMETERS = 8
# issue 57 extends the rule to the collision


def test_no_function_of_the_methods_or_the_collision_takes_more_than_eight_parameters():
    import ast

    crowded = []
    for path in sorted([*(PACKAGE / "methods").glob("*.py"), *(PACKAGE / "collision").glob("*.py")]):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
                arguments = node.args
                count = len(arguments.posonlyargs) + len(arguments.args) + len(arguments.kwonlyargs)
                count += (arguments.vararg is not None) + (arguments.kwarg is not None)
                name = f"{path.parent.name}/{path.name} {getattr(node, 'name', 'lambda')}"
                if count > MOST_PARAMETERS:
                    crowded.append(f"{name}:{node.lineno} ({count})")
    assert crowded == []


def test_no_module_imports_a_private_name_of_another():
    """Issue 57: what a module takes from another of the package is public there (a name with a
    leading underscore is the module's own)."""
    import ast

    private = []
    for name in _modules():
        for node in ast.walk(ast.parse((PACKAGE / name).read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and (node.level > 0 or (node.module or "").startswith("contactlab")):
                private += [
                    f"{name}:{node.lineno} {alias.name}"
                    for alias in node.names
                    if alias.name.startswith("_") and not alias.name.startswith("__")
                ]
    assert private == []


# the public names two modules may both define: one interface, each module its own case of it —
# every method's Options and step, every peer engine's World, and simulate(), contactlab's own or a
# peer engine's (contactlab.peers), which returns the same Run
SHARED_NAMES = {"Options", "step", "World", "simulate"}


def test_one_name_one_meaning():
    """Issue 36, item 5: no two modules define a public function or class of the same name
    (``integrate`` was a quaternion step and penalty's stage 4; ``run`` a study and the loop)."""
    import ast
    from collections import defaultdict

    where = defaultdict(list)
    for name in _modules():
        for node in ast.parse((PACKAGE / name).read_text(encoding="utf-8")).body:
            if isinstance(node, (ast.FunctionDef, ast.ClassDef)) and not node.name.startswith("_"):
                where[node.name].append(name)
    twice = {name: modules for name, modules in where.items() if len(modules) > 1}
    assert set(twice) <= SHARED_NAMES, {name: twice[name] for name in set(twice) - SHARED_NAMES}


def test_the_suite_says_why_it_skipped_a_test(tmp_path):
    # issue 37: a summary line "25 skipped" hid that the FCLIB tests had no data; pytest's options
    # in pyproject.toml must list each skip with its reason
    (tmp_path / "test_skips.py").write_text(
        'import pytest\n\n\ndef test_needs_something():\n    pytest.skip("the widget is absent")\n'
    )
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "pytest",
            "-c",
            str(ROOT / "pyproject.toml"),
            "--rootdir",
            str(tmp_path),
            "-n0",
            "-p",
            "no:cacheprovider",
            str(tmp_path),
        ],
        cwd=tmp_path,
        capture_output=True,
        text=True,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    assert "SKIPPED" in result.stdout and "the widget is absent" in result.stdout
