"""Reading TOML text (``tomllib`` on Python 3.11+, ``tomli`` on 3.10) with one-sentence errors.

Besides the syntax, two things TOML parsers accept are refused here, for every document and
every ``--set`` value: tables and arrays nested deeper than :data:`MAX_NESTING` (the parser
recurses once per level, so a document nested 100,000 deep would exhaust Python's stack),
and integers outside the 64-bit range the TOML specification allows (Python would take any
size, and a thousand-digit ``mass`` cannot become a float).
"""

from __future__ import annotations

import re
import sys
from typing import Any

from ..errors import InputError
from ..validation import WHOLE_NUMBERS

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised on Python 3.10 only
    import tomli as tomllib

TOMLDecodeError = tomllib.TOMLDecodeError

MAX_NESTING = 32  # tables and arrays inside one another, at most

_WHERE = re.compile(r"\s*\((?:at line (\d+), column (\d+)|at end of document)\)\s*$")


def loads(text: str, field: str = "") -> dict[str, Any]:
    """The TOML document ``text`` as a dict; TOMLDecodeError on a syntax error, InputError
    naming ``field`` for nesting deeper than MAX_NESTING or an integer beyond 64 bits."""
    try:
        document = tomllib.loads(text)
    except RecursionError:
        raise InputError(field, _too_deep()) from None
    except TOMLDecodeError:
        raise
    except ValueError:  # an integer of more digits than Python converts
        raise InputError(field, "this is not valid TOML (a number of thousands of digits)") from None
    _check_values(document, field)
    return document


def parse_toml(text: str) -> dict[str, Any]:
    """The document as a dict; InputError with field "line L, column C" on a syntax error."""
    try:
        return loads(text)
    except TOMLDecodeError as error:
        message = _first_line(error) or "invalid syntax"
        match = _WHERE.search(message)
        field = ""
        if match:
            message = message[: match.start()]
            field = f"line {match.group(1)}, column {match.group(2)}" if match.group(1) else "end of file"
        message = message[:1].lower() + message[1:]
        raise InputError(field, f"this is not valid TOML ({message})") from None


def _first_line(error):
    return str(error).splitlines()[0] if str(error) else ""


def _too_deep():
    return f"tables and arrays are nested more than {MAX_NESTING} levels deep (a scene needs 5 at most)"


def _check_values(document, field):
    """InputError for nesting deeper than MAX_NESTING or an integer outside WHOLE_NUMBERS
    (walked without recursion, so any depth the parser returned is safe to look at)."""
    pending = [(document, 1)]
    while pending:
        value, depth = pending.pop()
        if isinstance(value, (dict, list)):
            if depth > MAX_NESTING:
                raise InputError(field, _too_deep())
            children = value.values() if isinstance(value, dict) else value
            pending.extend((child, depth + 1) for child in children)
        elif (
            isinstance(value, int) and not isinstance(value, bool) and not WHOLE_NUMBERS[0] <= value <= WHOLE_NUMBERS[1]
        ):
            raise InputError(
                field,
                f"an integer of {len(str(abs(value)))} digits is outside the 64-bit range "
                f"TOML allows (±9.2e18); write a float such as 1e30 for a huge number",
            )
