"""Issue 22: the documentation site builds with ``mkdocs build --strict`` (a link to a page, file or
heading the site lacks, a page left out of the nav, or a docstring griffe cannot read fails it), its API reference
holds the docstrings, and its
example gallery shows every script of examples/ and every notebook, in full."""

import ast
import html
import importlib.util
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"
# what `pip install '.[docs]'` brings: the module each of its tools is imported as
TOOLS = {"mkdocs": "mkdocs", "mkdocs-material": "material", "mkdocstrings[python]": "mkdocstrings_handlers.python"}


def _missing_tools():
    missing = []
    for name, module in TOOLS.items():
        try:
            found = importlib.util.find_spec(module) is not None
        except ModuleNotFoundError:  # a parent package absent
            found = False
        if not found:
            missing.append(name)
    return missing


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    missing = _missing_tools()
    if missing:
        pytest.skip(f"{', '.join(missing)} not installed (pip install '.[docs]'): the site is not built")
    out = tmp_path_factory.mktemp("site")
    environment = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    result = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
        env=environment,
    )
    assert result.returncode == 0, result.stderr[-4000:]
    return out


def _text(path):
    """The words a reader sees on a built page: tags dropped, entities read, spaces collapsed."""
    page = path.read_text(encoding="utf-8")
    page = re.sub(r"<(script|style)\b.*?</\1>", " ", page, flags=re.DOTALL)
    return _words(html.unescape(re.sub(r"<[^>]+>", "", page)))


def _words(text):
    return " ".join(text.split())


def _docstring(path, name):
    tree = ast.parse(path.read_text(encoding="utf-8"))
    return next(ast.get_docstring(node) for node in tree.body if getattr(node, "name", None) == name)


def test_the_site_builds_strict_and_the_api_page_holds_the_docstrings(site):
    page = _text(site / "api" / "simulation" / "index.html")
    docstring = _docstring(ROOT / "src" / "contactlab" / "simulation.py", "simulate")
    # as written in the source, less reST markup: ``code`` and :func:`target` show as their text
    docstring = re.sub(r":\w+:`~?([\w.]+)`", r"\1", docstring).replace("``", "")
    for paragraph in docstring.split("\n\n"):
        assert _words(paragraph) in page
    # the signature, on one line or wrapped by a formatter (mkdocstrings uses ruff or black when present)
    # (with the parameters' annotations, which the site shows)
    assert re.search(
        r"simulate\(\s*model(:\s*Model)?,\s*method(:\s*str)?\s*=\s*['\"]impulse['\"],\s*dt(:\s*float)?\s*=\s*0\.004",
        page,
    )
    # a Sphinx role that names a documented object became a link to it
    assert 'href="#contactlab.threads.set_threads"' in (site / "api" / "simulation" / "index.html").read_text()
    # dataclass fields are documented by the attribute docstring under them
    methods = _text(site / "api" / "methods" / "index.html")
    assert "iterations: int = 100 sweeps per step (at most)" in methods


def test_the_gallery_shows_every_example_in_full(site):
    index = _text(site / "examples" / "index.html")
    scripts = sorted(EXAMPLES.glob("*.py"))
    notebooks = sorted((EXAMPLES / "notebooks").glob("*.ipynb"))
    assert scripts and notebooks
    for script in scripts:
        assert script.name in index, f"the gallery does not list {script.name}"
        page = site / "examples" / script.stem / "index.html"
        assert page.is_file(), f"no gallery page for {script.name} (docs/examples/{script.stem}.md)"
        assert _words(script.read_text(encoding="utf-8")) in _text(page)
    for notebook in notebooks:
        assert f"notebooks/{notebook.name}" in index, f"the gallery does not list {notebook.name}"
        page = _text(site / "examples" / notebook.stem / "index.html")
        cells = json.loads(notebook.read_text(encoding="utf-8"))["cells"]
        for cell in cells:
            if cell["cell_type"] == "code":
                assert _words("".join(cell["source"])) in page
