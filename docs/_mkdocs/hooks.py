"""MkDocs hooks for the documentation site (mkdocs.yml names this file under ``hooks``).

* A notebook is shown by a line ``<!-- notebook: examples/notebooks/NAME.ipynb -->`` in a page:
  its Markdown cells as text (headings one level down), its code cells as Python listings, read from the repository at
  build time (no Jupyter needed to build).
"""

import json
import os
import re

NOTEBOOK = re.compile(r"^<!-- notebook: (\S+\.ipynb) -->$", re.MULTILINE)
ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def notebook_markdown(path):
    with open(os.path.join(ROOT, path), encoding="utf-8") as file:
        cells = json.load(file)["cells"]
    parts = []
    for cell in cells:
        source = "".join(cell["source"]).strip()
        if cell["cell_type"] == "markdown":     # its headings one level down, under the page's own
            parts.append(re.sub(r"^#", "##", source, flags=re.MULTILINE))
        elif cell["cell_type"] == "code" and source:
            parts.append(f"```python\n{source}\n```")
    return "\n\n".join(parts)


def on_page_markdown(markdown, page, config, files):
    return NOTEBOOK.sub(lambda match: notebook_markdown(match.group(1)), markdown)
