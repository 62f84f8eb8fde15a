"""The one error type users see.

Every mistake in user input (a scene file, a command-line option, a value passed to the
builder) raises :class:`InputError` with a single sentence that names the field, what was
expected and what was found. The command line prints that sentence and exits with code 2;
it never shows a traceback for these.
"""


class InputError(ValueError):
    """Bad user input, described in one sentence.

    Attributes
    ----------
    field: dotted path of the offending field (``"bodies[0].mass"``), or ``""``.
    """

    def __init__(self, field: str, message: str):
        self.field = field
        self.message = message
        super().__init__(f"{field}: {message}" if field else message)


class SimulationDiverged(RuntimeError):
    """The state became non-finite: the time step is too large for the scene (or a stiffness too high).

    Attributes: ``time``, the simulated time [s] at which it was found (None if unknown)."""

    def __init__(self, message: str, time=None):
        super().__init__(message)
        self.time = time


class StabilityWarning(UserWarning):
    """A setting that will likely make the run blow up or ring (e.g. a penalty stiffness that
    explicit integration cannot follow at the chosen time step). The command line prints it as
    one line on stderr; the run goes on."""
