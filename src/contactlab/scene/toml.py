"""Reading TOML text (``tomllib`` on Python 3.11+, ``tomli`` on 3.10) with one-sentence errors."""

import re
import sys

from ..errors import InputError

if sys.version_info >= (3, 11):
    import tomllib
else:                                   # pragma: no cover - exercised on Python 3.10 only
    import tomli as tomllib

TOMLDecodeError = tomllib.TOMLDecodeError

_WHERE = re.compile(r"\s*\((?:at line (\d+), column (\d+)|at end of document)\)\s*$")


def parse_toml(text):
    """The document as a dict; InputError with field "line L, column C" on a syntax error."""
    try:
        return tomllib.loads(text)
    except TOMLDecodeError as error:
        message = str(error).splitlines()[0] if str(error) else "invalid syntax"
        match = _WHERE.search(message)
        field = ""
        if match:
            message = message[:match.start()]
            field = f"line {match.group(1)}, column {match.group(2)}" if match.group(1) else "end of file"
        message = message[:1].lower() + message[1:]
        raise InputError(field, f"this is not valid TOML ({message})") from None
