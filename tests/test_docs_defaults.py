"""docs/scene-format.md states every default the code has (issue 22: it gave wrong ones): each
method's table lists exactly the fields of its Options with their defaults, and the
[simulation] and [[materials]] tables the schema's."""

import dataclasses
import re
from pathlib import Path

import pytest

from contactlab import methods
from contactlab.scene.schema import MATERIAL, SIMULATION
from contactlab.scene.toml import loads

DOC = (Path(__file__).resolve().parents[1] / "docs" / "scene-format.md").read_text(encoding="utf-8")
ROW = re.compile(r"^\| `(\w+)` \|[^|]*\| (.+?) \| .*\|$")


def documented(heading):
    """key -> default text of the table under the Markdown ``heading`` (up to the next heading)."""
    section = DOC.split(heading + "\n", 1)[1].split("\n#", 1)[0]
    return {match[1]: match[2].strip() for line in section.splitlines() if (match := ROW.match(line))}


def value(text):
    """A documented default as the value it spells (`0.2` -> 0.2, `"auto"` -> "auto")."""
    return loads("value = " + text.strip("`"))["value"]


@pytest.mark.parametrize("name", methods.AVAILABLE)
def test_each_method_table_lists_its_options_with_their_defaults(name):
    table = documented(f"### `[method.{name}]`")
    fields = {field.name: field.default for field in dataclasses.fields(methods.get(name).Options)}
    assert set(table) == set(fields)
    for key, text in table.items():
        if " / " in text:  # a default that depends on another option: both are named
            assert fields[key] is None, key
            continue
        assert value(text) == fields[key], (key, text, fields[key])


def test_the_simulation_and_material_tables_give_the_schema_defaults():
    for heading, schema in (("## `[simulation]`", SIMULATION), ("## `[[materials]]`", MATERIAL)):
        table = documented(heading)
        assert set(table) == set(schema), heading
        for key, text in table.items():
            if text != "*required*":
                assert value(text) == schema[key].default, (heading, key)
