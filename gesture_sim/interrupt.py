"""The one record of a SIGINT/SIGTERM that ended the run, readable by every stage.

The command line's signal handler (:mod:`gesture_sim.cli`) calls :func:`note` and raises
:class:`Interrupted`. Python drops an exception raised where it cannot propagate — a weakref
callback or ``__del__`` that happened to run when the signal arrived (the import system's
module-lock callback, for one) prints "Exception ignored in ..." and carries on — so the raise
alone can be lost and the run would finish as if nothing happened, replacing the user's previous
outputs. :func:`check` raises the interruption again: long loops call it, and every atomic output
calls it before its rename, so a run that was signalled never publishes an output.
"""

from __future__ import annotations

import signal
from collections.abc import Callable
from typing import Any

#: The signal that ended the run, once one has arrived (0 before).
_received = 0


class Interrupted(KeyboardInterrupt):
    """SIGINT or SIGTERM arrived (see the module docstring); ``signum`` says which."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def note(signum: int) -> None:
    """Record that ``signum`` ended the run."""
    global _received
    _received = int(signum)


def take(signum: int) -> None:
    """A signal handler's first step: ignore further SIGINT/SIGTERM (the cleanup that follows
    must not be cut short) and record ``signum`` (kept where a raise would be dropped)."""
    for s in (signal.SIGINT, signal.SIGTERM):
        signal.signal(s, signal.SIG_IGN)
    note(signum)


def received() -> int:
    """The signal that ended the run, or 0 if none has arrived."""
    return _received


def check() -> None:
    """Raise :class:`Interrupted` if a signal has arrived (even one whose first raise was lost)."""
    if _received:
        raise Interrupted(_received)


def reset() -> None:
    """Forget a recorded signal (for in-process callers that handled it, such as tests)."""
    global _received
    _received = 0


def quiet_dropped(previous_hook: Callable[[Any], object]) -> Callable[[Any], None]:
    """A ``sys.unraisablehook`` that says nothing of the signal's own exception where Python had
    to drop it (a KeyboardInterrupt or SystemExit once a signal is recorded: it is acted on by
    :func:`check`) and passes every other unraisable exception to ``previous_hook``."""
    def hook(unraisable: Any) -> None:   # a sys.UnraisableHookArgs
        if not (_received and isinstance(unraisable.exc_value, KeyboardInterrupt | SystemExit)):
            previous_hook(unraisable)
    return hook
