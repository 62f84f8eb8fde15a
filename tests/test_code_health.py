"""Issue 23: the habits of a maintained library, held by the suite — ruff's lint and format clean
over src/ and tests/ (the settings in pyproject.toml) and no module over 600 lines. That the
module map (docs/modules.md) names every module, in one layer, is tests/test_layers.py's."""

import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "src" / "contactlab"
LONGEST_MODULE = 600  # lines: a module longer than this holds more than one concern (issue 23)


def _ruff(*arguments):
    if shutil.which("ruff") is None:
        pytest.skip("ruff is not installed (pip install '.[test]' brings it)")
    return subprocess.run(["ruff", *arguments, "src", "tests"], cwd=ROOT, capture_output=True, text=True)


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


def test_no_module_is_longer_than_six_hundred_lines():
    lengths = {name: len((PACKAGE / name).read_text(encoding="utf-8").splitlines()) for name in _modules()}
    assert len(lengths) > 100
    assert {name: n for name, n in lengths.items() if n > LONGEST_MODULE} == {}
