"""The one error type users see.

Every mistake in user input (a scene file, a command-line option, a value passed to the
builder) raises :class:`InputError` with a single sentence that names the field, what was
expected and what was found. The command line prints that sentence and exits with code 2;
it never shows a traceback for these.

However long or odd the input it quotes, the sentence stays one short line: :func:`shorten`
cuts it (in :class:`InputError` itself, so every message is cut the same way).
"""

from __future__ import annotations

import re
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .simulation import Run

LONGEST_WORD = 80  # characters: a longer run without spaces (a key, a value, a path) is cut
LONGEST_MESSAGE = 500  # characters: a longer message is cut
ELLIPSIS = "…"

_LINE_BREAKING = re.compile("[\x00-\x1f\x7f\x85\u2028\u2029]")  # control characters, line breaks
_LONG_WORD = re.compile(rf"\S{{{LONGEST_WORD + 1},}}")


def _cut(text, limit):
    """``text``, or its start and end joined by an ellipsis in ``limit`` characters."""
    if len(text) <= limit:
        return text
    head = (limit - 1) // 2
    return text[:head] + ELLIPSIS + text[len(text) - (limit - 1 - head) :]


def shorten(text: object) -> str:
    """``text`` as one short line: control characters and line breaks written as escapes
    (``\\n``), every run of more than LONGEST_WORD non-space characters and then the whole
    beyond LONGEST_MESSAGE characters cut in the middle to an ellipsis. Cutting twice changes
    nothing more."""
    text = _LINE_BREAKING.sub(lambda match: repr(match.group())[1:-1], str(text))
    text = _LONG_WORD.sub(lambda match: _cut(match.group(), LONGEST_WORD), text)
    return _cut(text, LONGEST_MESSAGE)


def first_line(error: BaseException) -> str:
    """The first line of an exception's message, or its type's name when it has none: what a
    one-line error says of a library's failure."""
    text = str(error).strip()
    return text.splitlines()[0] if text else type(error).__name__


class InputError(ValueError):
    """Bad user input, described in one sentence.

    Attributes
    ----------
    field: dotted path of the offending field (``"bodies[0].mass"``), or ``""``.
    message: the sentence. Both are kept as :func:`shorten` makes them: one line, long keys
    and values cut.
    """

    def __init__(self, field: str, message: str) -> None:
        self.field = shorten(field)
        self.message = shorten(message)
        super().__init__(f"{self.field}: {self.message}" if self.field else self.message)


class SimulationDiverged(RuntimeError):
    """A run went wrong: a health check of :mod:`contactlab.health` failed (a non-finite state,
    a speed beyond the scene's scale, energy from nowhere, a contact deep enough to pass through).

    Attributes: ``time``, the simulated time [s] at which it was found (None if unknown);
    ``run``, the :class:`contactlab.simulation.Run` up to then (its summary's ``"diverged"``
    says what and when), or None."""

    def __init__(self, message: str, time: float | None = None, run: Run | None = None) -> None:
        super().__init__(message)
        self.time = time
        self.run = run
