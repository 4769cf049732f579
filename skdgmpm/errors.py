"""Exceptions with one-line messages for the user."""


class InputError(ValueError):
    """Bad user input: the message names the file (if any), the key and the value."""


class InstabilityError(RuntimeError):
    """A run produced non-finite values or lost hyperbolicity."""

    def __init__(self, message, *, step=None, time=None, particle=None):
        super().__init__(message)
        self.step = step
        self.time = time
        self.particle = particle


class OutputError(RuntimeError):
    """Writing the outputs failed (a full disk, ...): the message says what and what was kept."""
