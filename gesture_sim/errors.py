"""The one exception type the command line turns into a one-line error message."""


class GestureSimError(Exception):
    """A user-facing error: bad input, missing device, incompatible model.

    The CLI prints ``gesture-sim: error: <message>`` and exits with status 2; no traceback.
    Messages should be one line and say what was wrong and, where possible, what to do.
    """
